"""Reference online compensator in plain Python (no numpy, no numba): the spec a C++ /
ROS implementer follows. It loads the JSON of ``Compensator.to_json`` (schema
``i2ris-calib.compensator/2``, or ``/1`` without delay and coupling; docs/compensate.md
"Online use") and steps exactly as ``i2ris_calib.compensation.kernel`` does (``_step``,
``step_one``, ``step_pair``, ``advance``); test_online.py checks it to 1e-9.

Per axis: ``c`` envelope coefficients (gpi/egpi/egpi_c: a1..a6; agpi: a1..a4 of side p,
a1..a4 of side n, theta0), ``r``/``p`` thresholds and weights (agpi: side p then side n),
``kappa``, ``v_f`` (null = inf), ``deadband_counts``, ``v_limits``, ``max_counts_per_s``
(null = none), ``quantum``, ``tol_deg``, ``sign``, ``delay_s`` (the target a step gets
is the angle wanted that long after it: nothing else changes), ``coupling`` (null, or
a two-tendon GPI ``c``/``r``/``p`` on the other motor's signed counts, whose output is
added to this axis's: the step inverts its own tendons on the target less it) and
``state``.
"""

from __future__ import annotations

import copy
import json
import math

GPI, EGPI, EGPI_C, AGPI = "gpi", "egpi", "egpi_c", "agpi"
INIT, UP, HOLD, DOWN = 2, 1, 0, -1
OK, ABOVE, BELOW, RATE, GAP = 0, 1, 2, 3, 4


def _narrowed(x, fx, target, lo, flo, hi, fhi):
    """The bracket ``(lo, flo, hi, fhi)`` (ends and their outputs) narrowed by a point
    ``x`` inside it whose output ``fx`` is not the target: it replaces the end on its
    side of the target."""
    if fx < target:
        return x, fx, hi, fhi
    return lo, flo, x, fx


def _play(w, wo, off, m, al, bl, ar, br, r, p, side, u):
    acc = 0.0
    for i in range(off, off + m):
        if side == INIT:
            wi = min(max(0.0, al * u + bl - r[i]), ar * u + br + r[i])
        elif side == UP:
            wi = max(al * u + bl - r[i], w[i])
        elif side == DOWN:
            wi = min(ar * u + br + r[i], w[i])
        else:
            wi = w[i]
        wo[i] = wi
        acc += p[i] * wi
    return acc


def _side(v_prev, u, init):
    return INIT if init else UP if u > v_prev else DOWN if u < v_prev else HOLD


class Axis:
    def __init__(self, a):
        self.kind = a["kernel_kind"]
        self.coupling = None
        if a.get("coupling") is not None:  # a two-tendon GPI on the other motor's counts
            cp, sc = a["coupling"], a["state"]["coupling"]
            self.coupling = Axis({
                "kernel_kind": AGPI, "c": cp["c"], "r": cp["r"], "p": cp["p"], "kappa": 1.0,
                "v_f": None, "deadband_counts": 0.0, "v_limits": [-math.inf, math.inf],
                "max_counts_per_s": None, "quantum": 0.0, "tol_deg": 0.0, "sign": 1.0,
                "state": {"operators": [sc["operators"], [0.0] * len(cp["p"])],
                          "direction": 1, "anchor": sc["other_counts"],
                          "last_input": sc["other_counts"], "last_output_deg": sc["coupling_deg"],
                          "init": False, "last_move_s": 0.0, "time_s": 0.0},
            })  # fmt: skip
        self.last = (0.0, 0.0, 0, 0.0)  # command, output (robot sign), status, coupling
        self.c, self.r, self.p = list(a["c"]), list(a["r"]), list(a["p"])
        self.kappa = a["kappa"]
        self.vf = math.inf if a["v_f"] is None else a["v_f"]
        self.db = a["deadband_counts"]
        self.lo, self.hi = a["v_limits"]
        self.rate = math.inf if a["max_counts_per_s"] is None else a["max_counts_per_s"]
        self.q, self.tol_deg, self.sign = a["quantum"], a["tol_deg"], a["sign"]
        s = a["state"]
        self.w = [list(row) for row in s["operators"]]
        self.d, self.anchor = int(s["direction"]), s["anchor"]
        self.v_prev, self.y_prev = s["last_input"], s["last_output_deg"]
        self.init, self.t_move, self.t = bool(s["init"]), s["last_move_s"], s["time_s"]

    def family(self, fam, w, wo, u, side):
        c, r, p, vf, v_prev = self.c, self.r, self.p, self.vf, self.v_prev
        if self.kind == AGPI:
            m = len(p) // 2
            up, un = max(u, 0.0), max(-u, 0.0)
            sp = sn = INIT
            if side != INIT:
                sp, sn = _side(max(v_prev, 0.0), up, False), _side(max(-v_prev, 0.0), un, False)
            yp = _play(w, wo, 0, m, c[0], c[1], c[2], c[3], r, p, sp, up)
            return c[8] + yp - _play(w, wo, m, m, c[4], c[5], c[6], c[7], r, p, sn, un)
        if self.kind == EGPI_C:
            g, kr = (c[2] * u + c[3], 1.0) if u > vf else (c[4] * u + c[5], self.kappa)
        elif fam == 1:
            g, kr = c[4] * u + c[5], self.kappa
        else:
            g, kr = c[2] * u + c[3], 1.0
        g1 = (
            c[2] * vf + c[3]
            if self.kind == EGPI_C and side == DOWN and v_prev > vf >= u
            else math.inf
        )
        acc = 0.0
        for i in range(len(p)):
            if side == INIT:
                wi = min(max(0.0, c[0] * u + c[1] - r[i]), g + kr * r[i])
            elif side == UP:
                wi = max(c[0] * u + c[1] - r[i], w[i])
            elif side == DOWN:
                wi = min(g + kr * r[i], min(g1 + r[i], w[i]))
            else:
                wi = w[i]
            wo[i] = wi
            acc += p[i] * wi
        return acc

    def direction(self, u, init):
        d, a, db = self.d, self.anchor, self.db
        if init:
            return 1, u
        if d > 0:
            return (1, u) if u > a else (-1, u) if a - u > db else (1, a)
        return (-1, u) if u < a else (1, u) if u - a > db else (-1, a)

    def select(self, u, init):
        if self.kind != EGPI:
            return 0
        return 0 if self.direction(u, init)[0] > 0 else (1 if u <= self.vf else 0)

    def exact(self, u, init):
        fam = self.select(u, init)
        return self.family(fam, self.w[fam], [0.0] * len(self.p), u, _side(self.v_prev, u, init))

    def slope(self, fam, u, side):
        """d output / d input of the piece at ``u`` (kernel._slope): the weights of the
        operators that move with the input, times the envelope's slope."""
        c, r, p, w = self.c, self.r, self.p, self.w[fam]

        def moving(off, m, a, g, kr, g1, up):
            acc = 0.0
            for i in range(off, off + m):
                if (g - r[i] >= w[i]) if up else (g + kr * r[i] <= min(g1 + r[i], w[i])):
                    acc += p[i]
            return a * acc

        if self.kind == AGPI:
            m = len(p) // 2
            if u > 0.0 or (u == 0.0 and side == DOWN):
                sp = _side(max(self.v_prev, 0.0), u, False)
                if sp == HOLD:
                    return 0.0
                a, b = (c[0], c[1]) if sp == UP else (c[2], c[3])
                return moving(0, m, a, a * u + b, 1.0, math.inf, sp == UP)
            sn = _side(max(-self.v_prev, 0.0), -u, False)
            if sn == HOLD:
                return 0.0
            a, b = (c[4], c[5]) if sn == UP else (c[6], c[7])
            return moving(m, m, a, a * -u + b, 1.0, math.inf, sn == UP)
        if side == UP:
            return moving(0, len(p), c[0], c[0] * u + c[1], 1.0, math.inf, True)
        g1 = math.inf
        if self.kind == EGPI_C:
            a, b, kr = (c[2], c[3], 1.0) if u > self.vf else (c[4], c[5], self.kappa)
            if self.v_prev > self.vf >= u:
                g1 = c[2] * self.vf + c[3]
        elif fam == 1:
            a, b, kr = c[4], c[5], self.kappa
        else:
            a, b, kr = c[2], c[3], 1.0
        return moving(0, len(p), a, a * u + b, kr, g1, False)

    def root(self, fam, side, lo, hi, target):
        scratch = [0.0] * len(self.p)

        def f(x):
            return self.family(fam, self.w[fam], scratch, x, side)

        flo = f(lo)
        if target <= flo:
            return lo
        fhi = f(hi)
        if target >= fhi:
            return hi
        tol_y = 1e-12 * max(1.0, abs(target))
        if side in (UP, DOWN):  # Newton on the piecewise linear output (kernel._root)
            x, fx = (hi, fhi) if side == UP else (lo, flo)
            for _ in range(16):
                s = self.slope(fam, x, side)
                if not s > 0.0:
                    break
                xn = x - (fx - target) / s
                if not lo < xn < hi:
                    break
                x, fx = xn, f(xn)
                if abs(fx - target) <= tol_y:
                    return x
                lo, flo, hi, fhi = _narrowed(x, fx, target, lo, flo, hi, fhi)
        bisect = False
        for _ in range(200):
            width = hi - lo
            if width <= 1e-13 * max(1.0, abs(hi)) or fhi - flo <= tol_y:
                break
            if bisect or fhi <= flo:
                x = 0.5 * (lo + hi)
            else:
                x = lo + (target - flo) * (hi - lo) / (fhi - flo)
                if not (lo < x < hi):
                    x = 0.5 * (lo + hi)
            fx = f(x)
            if abs(fx - target) <= tol_y:
                return x
            lo, flo, hi, fhi = _narrowed(x, fx, target, lo, flo, hi, fhi)
            bisect = (hi - lo) > 0.5 * width
        return lo if abs(flo - target) <= abs(fhi - target) else hi

    def choose(self, cands, tk, init):
        tol = max(self.tol_deg, 1e-10 * max(1.0, abs(tk)))
        best_e = min(e for _, e, _ in cands)
        met = best_e <= tol
        lim = tol if met else best_e + 1e-12 * max(1.0, best_e)
        best = None
        for x, e, keep in cands:
            if e > lim:
                continue
            if init:
                score = -x
            elif met or tk == self.y_prev:
                score = -abs(x - self.v_prev)
            elif tk < self.y_prev:
                score = self.v_prev - x
            else:
                score = x - self.v_prev
            kp = keep and met
            if best is None or (kp and not best[2]) or (kp == best[2] and score > best[3]):
                best = (x, e, kp, score)
        return best[0], best[1]

    def candidate(self, x, tk, init):
        return (x, abs(self.exact(x, init) - tk), init or self.direction(x, init)[0] == self.d)

    def apply(self, u, init):
        """The state update of input ``u`` (every family, then v'); the output after it."""
        side = _side(self.v_prev, u, init)
        for f in range(2 if self.kind == EGPI else 1):
            new = [0.0] * len(self.p)
            self.family(f, self.w[f], new, u, side)
            self.w[f] = new
        fam = self.select(u, init)
        self.d, self.anchor = self.direction(u, init)
        if self.kind == AGPI:
            m = len(self.p) // 2
            y = self.c[8]
            for i in range(2 * m):
                y += (1.0 if i < m else -1.0) * self.p[i] * self.w[0][i]
        else:
            y = sum(pi * wi for pi, wi in zip(self.p, self.w[fam], strict=True))
        self.v_prev, self.y_prev, self.init = u, y, False
        return y

    def advance(self, counts, other_counts, dt):
        """Carry the state through signed counts already sent (kernel.advance)."""
        for k, v in enumerate(counts):
            self.apply(self.sign * v, self.init)
            if self.coupling is not None:
                self.coupling.apply(other_counts[k], False)
            self.t += dt
        self.t_move = self.t

    def step(self, target_robot_deg, dt, other_counts=0.0):
        """(signed counts, predicted angle, status) of one step (kernel.step_one);
        ``other_counts``: the other motor's signed counts now (a coupled axis)."""
        yc = 0.0
        if self.coupling is not None:
            yc = self.coupling.apply(other_counts, False)
        tk = self.sign * target_robot_deg - yc
        t_k = self.t + dt
        init, v_prev, lo, hi, q = self.init, self.v_prev, self.lo, self.hi, self.q
        a_lim, b_lim = lo, hi
        if not init:
            step = self.rate * dt
            if not math.isfinite(step):
                step = math.inf
            elif 0 < q and step < q and self.rate * (t_k - self.t_move) >= q * (1.0 - 1e-9):
                step = q
            a_lim = min(max(lo, v_prev - step), v_prev)
            b_lim = max(min(hi, v_prev + step), v_prev)
        if q > 0:
            qa, qb = math.ceil(a_lim / q - 1e-9) * q, math.floor(b_lim / q + 1e-9) * q
            qlo, qhi = math.ceil(lo / q - 1e-9) * q, math.floor(hi / q + 1e-9) * q
        else:
            qa, qb, qlo, qhi = a_lim, b_lim, lo, hi
        cands = [] if init else [(v_prev, abs(self.y_prev - tk), True)]
        bps = []
        if self.kind == EGPI and not init:
            bps = [self.vf, self.anchor + self.db, self.anchor - self.db]
        elif self.kind == EGPI_C:
            bps = [self.vf]
        elif self.kind == AGPI:
            bps = [0.0]
        sides = [(lo, hi, INIT)] if init else []
        if not init and hi > v_prev and (self.kind == EGPI or tk > self.y_prev):
            sides.append((v_prev, hi, UP))
        if not init and lo < v_prev and (self.kind == EGPI or tk < self.y_prev):
            sides.append((lo, v_prev, DOWN))
        for s_lo, s_hi, side in sides:
            edges = sorted([s_lo, *[b for b in bps if s_lo < b < s_hi], s_hi])
            ne = len(edges)
            for j in range(ne - 1):
                e0, e1 = edges[j], edges[j + 1]
                if e1 <= e0:
                    continue
                mid = 0.5 * (e0 + e1)
                fam = self.select(mid, init)
                x = self.root(fam, side, e0, e1, tk)
                eps = 1e-9 * max(1.0, abs(x))
                if x == e0 and not (init or (side == DOWN and j == 0)):
                    x = min(e0 + eps, mid)
                elif x == e1 and not (init or (side == UP and j == ne - 2)):
                    x = max(e1 - eps, mid)
                cands.append(self.candidate(x, tk, init))
        best_r, best_r_err = self.choose(cands, tk, init)
        best_q = best_r
        if q > 0:
            qc = [] if init else [(v_prev, abs(self.y_prev - tk), True)]
            for xq in (math.floor(best_r / q) * q, math.ceil(best_r / q) * q):
                qc.append(self.candidate(min(max(xq, qlo), qhi), tk, init))
            best_q = self.choose(qc, tk, init)[0]
        tol = max(self.tol_deg, 1e-10 * max(1.0, abs(tk)))
        near = 1e-6 * max(1.0, abs(best_r))
        stat = OK
        if best_r_err > tol:
            y_best = self.exact(best_r, init)
            if tk > y_best and best_r >= hi - near:
                stat = ABOVE
            elif tk < y_best and best_r <= lo + near:
                stat = BELOW
            else:
                stat = GAP
        if best_r > b_lim or best_r < a_lim:
            best_r = min(max(best_r, a_lim), b_lim)
            best_q = qb if best_q > qb else qa if best_q < qa else best_q
            if stat == OK and abs(self.exact(best_r, init) - tk) > tol:
                stat = RATE
        elif best_q > qb or best_q < qa:
            best_q = qb if best_q > qb else qa
        # apply the command: every family, then v'
        u = best_q
        y = self.apply(u, init)
        if u != v_prev or init:
            self.t_move = t_k
        self.t = t_k
        self.last = (self.sign * u, self.sign * (y + yc), stat, yc)
        return self.last[:3]


def step_pair(a, b, ta, tb, dt, rounds=8):
    """Both axes of which at least one is coupled (kernel.step_pair): the uncoupled one
    first; two coupled ones by Gauss-Seidel, each step from a copy of the state before
    the sample, a given b's command, b given a's, a again, ..., until a step repeats its
    axis's command (or 2 rounds steps). Returns ((counts, predicted, status, settled)
    of a, of b)."""
    if b.coupling is None:
        b.step(tb, dt)
        a.step(ta, dt, b.last[0])
        return a.last[:3] + (True,), b.last[:3] + (True,)
    if a.coupling is None:
        a.step(ta, dt)
        b.step(tb, dt, a.last[0])
        return a.last[:3] + (True,), b.last[:3] + (True,)
    save = {id(a): copy.deepcopy(a), id(b): copy.deepcopy(b)}

    def restep(x, target, other_counts):
        x.__dict__.update(copy.deepcopy(save[id(x)]).__dict__)
        return x.step(target, dt, other_counts)[0]

    ub = b.sign * b.v_prev
    ua = restep(a, ta, ub)
    n, done, last_a = 1, False, True
    while n < 2 * rounds and not done:
        if last_a:
            u_new = restep(b, tb, ua)
            done, ub = u_new == ub, u_new
        else:
            u_new = restep(a, ta, ub)
            done, ua = u_new == ua, u_new
        n += 1
        last_a = not last_a
    if not done:  # the axis stepped before the last follows the other's command sent
        x, vo = (b, ua) if last_a else (a, ub)
        x.coupling = copy.deepcopy(save[id(x)].coupling)
        yc = x.coupling.apply(vo, False)
        u, y, st, yc_old = x.last
        x.last = (u, y + x.sign * (yc - yc_old), st, yc)
    return a.last[:3] + (done,), b.last[:3] + (done,)


def load(path):
    """{axis: Axis} of a compensator JSON."""
    with open(path, encoding="utf-8") as f:
        doc = json.load(f)
    assert doc["schema"] in ("i2ris-calib.compensator/1", "i2ris-calib.compensator/2")
    return {name: Axis(a) for name, a in doc["axes"].items()}
