"""Compiled sample-by-sample inversion of the GPI / EGPI / continuous EGPI (numba).

The forward models (:mod:`i2ris_calib.hysteresis.kernel`) map an input sequence to
an angle sequence; the operator states make the map stateful. The inverse walks the
target sequence once, carrying the *same* state as the forward kernels: at every
sample it chooses the input that brings the model's output closest to the target,
then advances the state with that input exactly as the forward recursion would.

Why a 1-D root find suffices: from a given state, every operator family's output
after one step to input ``u`` is a nondecreasing function of ``u`` on each side of
the previous input (loading: ``max(gamma_l(u) - r, w)``, unloading:
``min(gamma_r(u) + r, w)``, with nondecreasing envelopes), and the initial state
``min(max(0, gamma_l - r), gamma_r + r)`` is nondecreasing in ``u`` too. The only
non-monotone places are where the paper's EGPI switches its output between the two
families (at the flag point ``v_f`` and where ``v'`` changes sign after the dead
band) and where the continuous EGPI's initial state changes boundary at ``v_f``:
the candidate interval is split there ("regions"), and on each region the root is
bracketed and found by safeguarded regula falsi (bisection whenever the bracket
shrinks by less than half). Every candidate is re-evaluated with the exact forward
step and the best is kept (:func:`_choose`: smallest |error|; among inputs that all
meet the target, no reversal of ``v'`` if possible, then the smallest move; in a dead
zone where the output has not moved yet, the largest move toward the target). A target
inside an output discontinuity (the EGPI step at ``v_f``, the reversal jump of the
``r = 0`` operator when ``gamma_l != gamma_r``) is therefore approached as closely as
the model allows and flagged.

Conventions: ``c`` = envelope coefficients (a1..a6; GPI uses a5 = a3, a6 = a4),
``r``, ``p`` thresholds and weights (shape (m,)), ``kind`` one of the ``KIND_*``
codes, ``w`` operator states (2, m) (family 1 only used by the paper's EGPI).

:func:`invert` runs the compiled loop :data:`CHUNK` samples at a time, the state carried
across calls that return nothing: a Ctrl-C is raised between two of them, in Python,
never while numba converts returned arrays (that crashed: i2ris_calib/interrupts.py).

The state API the batch (:mod:`.inverse`) and the online compensator (:mod:`.online`)
share: :func:`start` (the model's state at rest at an input), :func:`advance` (carry a
state through inputs already sent: the one state update, :func:`_update`, that the
inverse also applies after choosing each command), ``invert(start_state=...)`` (invert
from such a state) and :class:`Resume` (the spike repair re-inverts only what its new
holds change). Online: :func:`step_one` (one axis; a coupled axis's coupling is advanced
with the other motor's counts first), :func:`step_pair` (two axes solved jointly).

Root finding (:func:`_root`): on a loading or unloading side the model output is
piecewise linear in the input, convex when loading and concave when unloading, so Newton
steps (:func:`_slope`) from the far end land on the root's piece exactly after as many
steps as pieces crossed; safeguarded regula falsi finishes otherwise.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from i2ris_calib.hysteresis.kinds import INVERSE_FAMILIES

KIND_GPI = 0
KIND_EGPI = 1
KIND_EGPI_C = 2
#: The two-tendon GPI (``agpi``): ``c`` = (a1_p, a2_p, a3_p, a4_p, a1_n, a2_n, a3_n, a4_n,
#: theta0), ``r`` / ``p`` = the two sides' thresholds and weights one after the other
#: (shape (2 m,)), one family whose state row holds ``w_p`` then ``w_n``; the input is
#: the signed command (side p sees ``max(u, 0)``, side n ``max(-u, 0)``)
KIND_AGPI = 3
#: Inverse family (a registry row's ``inverse``) -> its kind code: the families of
#: :data:`~i2ris_calib.hysteresis.kinds.INVERSE_FAMILIES` are in code order
FAMILY_CODES = dict(zip(INVERSE_FAMILIES, (KIND_GPI, KIND_EGPI, KIND_EGPI_C, KIND_AGPI),
                        strict=True))  # fmt: skip

STATUS_OK = 0
STATUS_ABOVE = 1
STATUS_BELOW = 2
STATUS_RATE = 3
STATUS_GAP = 4
STATUS_DELAY = 5

SIDE_INIT = 2
SIDE_UP = 1
SIDE_HOLD = 0
SIDE_DOWN = -1


@njit(cache=True)
def _play_side(w, wout, off, m, al, bl, ar, br, r, p, side, u):  # pragma: no cover
    """One GPI's weighted operator sum after one step to ``u`` (operators ``off ..
    off + m - 1`` of ``w`` -> ``wout``; initial state ``min(max(0, gl - r), gr + r)``,
    as :func:`i2ris_calib.hysteresis.kernel.play_operators`)."""
    acc = 0.0
    if side == SIDE_INIT:
        gl = al * u + bl
        g = ar * u + br
        for i in range(off, off + m):
            wi = min(max(0.0, gl - r[i]), g + r[i])
            wout[i] = wi
            acc += p[i] * wi
    elif side == SIDE_UP:
        g = al * u + bl
        for i in range(off, off + m):
            wi = max(g - r[i], w[i])
            wout[i] = wi
            acc += p[i] * wi
    elif side == SIDE_DOWN:
        g = ar * u + br
        for i in range(off, off + m):
            wi = min(g + r[i], w[i])
            wout[i] = wi
            acc += p[i] * wi
    else:
        for i in range(off, off + m):
            wout[i] = w[i]
            acc += p[i] * w[i]
    return acc


@njit(cache=True)
def _agpi(w, wout, c, r, p, v_prev, u, side):  # pragma: no cover
    """Two-tendon GPI output ``theta0 + Y_p[max(u, 0)] - Y_n[max(-u, 0)]`` after one
    step to the signed input ``u`` (each side steps from its own previous input; the
    side on the other side of zero steps to 0, i.e. holds once it is there)."""
    m = p.size // 2
    up = max(u, 0.0)
    un = max(-u, 0.0)
    if side == SIDE_INIT:
        sp = SIDE_INIT
        sn = SIDE_INIT
    else:
        sp = _side(max(v_prev, 0.0), up, False)
        sn = _side(max(-v_prev, 0.0), un, False)
    yp = _play_side(w, wout, 0, m, c[0], c[1], c[2], c[3], r, p, sp, up)
    yn = _play_side(w, wout, m, m, c[4], c[5], c[6], c[7], r, p, sn, un)
    return c[8] + yp - yn


@njit(cache=True)
def _family(kind, fam, w, wout, c, r, p, kappa, vf, v_prev, u, side):  # pragma: no cover
    """Output of operator family ``fam`` after one step to ``u`` (state -> ``wout``)."""
    if kind == KIND_AGPI:
        return _agpi(w, wout, c, r, p, v_prev, u, side)
    m = p.size
    acc = 0.0
    if side == SIDE_INIT:
        gl = c[0] * u + c[1]
        if kind == KIND_EGPI_C:
            if u > vf:
                g, kr = c[2] * u + c[3], 1.0
            else:
                g, kr = c[4] * u + c[5], kappa
        elif fam == 1:
            g, kr = c[4] * u + c[5], kappa
        else:
            g, kr = c[2] * u + c[3], 1.0
        for i in range(m):
            wi = min(max(0.0, gl - r[i]), g + kr * r[i])
            wout[i] = wi
            acc += p[i] * wi
    elif side == SIDE_UP:
        g = c[0] * u + c[1]
        for i in range(m):
            wi = max(g - r[i], w[i])
            wout[i] = wi
            acc += p[i] * wi
    elif side == SIDE_DOWN:
        g1 = np.inf
        if kind == KIND_EGPI_C:
            if u > vf:
                g, kr = c[2] * u + c[3], 1.0
            else:
                g, kr = c[4] * u + c[5], kappa
            if v_prev > vf >= u:
                g1 = c[2] * vf + c[3]
        elif fam == 1:
            g, kr = c[4] * u + c[5], kappa
        else:
            g, kr = c[2] * u + c[3], 1.0
        for i in range(m):
            wi = min(g + kr * r[i], min(g1 + r[i], w[i]))
            wout[i] = wi
            acc += p[i] * wi
    else:
        for i in range(m):
            wout[i] = w[i]
            acc += p[i] * w[i]
    return acc


@njit(cache=True)
def _direction(dstate, anchor, u, db, init):  # pragma: no cover
    """``v'`` state after input ``u``: (+1 loading / -1 unloading, anchor), as
    :func:`i2ris_calib.hysteresis.kernel.motion_direction`."""
    if init:
        return 1, u
    if dstate > 0:
        if u > anchor:
            return 1, u
        if anchor - u > db:
            return -1, u
        return 1, anchor
    if u < anchor:
        return -1, u
    if u - anchor > db:
        return 1, u
    return -1, anchor


@njit(cache=True)
def _select(kind, dstate, anchor, u, db, vf, init):  # pragma: no cover
    """Family whose output the model shows after input ``u`` (Eq20 for the EGPI)."""
    if kind != KIND_EGPI:
        return 0
    d, _ = _direction(dstate, anchor, u, db, init)
    if d > 0:
        return 0
    return 1 if u <= vf else 0


@njit(cache=True)
def _shown(kind, w, fam, c, p):  # pragma: no cover
    """The model output (deg) of the state ``w`` (2, m): family ``fam``'s weighted sum
    (``theta0 + Y_p - Y_n`` for the two-tendon GPI)."""
    if kind == KIND_AGPI:
        m = p.size // 2
        acc = c[8]
        for i in range(m):
            acc += p[i] * w[0, i]
        for i in range(m, 2 * m):
            acc -= p[i] * w[0, i]
        return acc
    acc = 0.0
    for i in range(p.size):
        acc += p[i] * w[fam, i]
    return acc


@njit(cache=True)
def _side(v_prev, u, init):  # pragma: no cover
    if init:
        return SIDE_INIT
    if u > v_prev:
        return SIDE_UP
    if u < v_prev:
        return SIDE_DOWN
    return SIDE_HOLD


@njit(cache=True)
def _exact(
    kind, w, scratch, c, r, p, kappa, vf, db, dstate, anchor, v_prev, u, init
):  # pragma: no cover
    """Model output (deg) after input ``u`` from the current state (state unchanged)."""
    fam = _select(kind, dstate, anchor, u, db, vf, init)
    side = _side(v_prev, u, init)
    return _family(kind, fam, w[fam], scratch, c, r, p, kappa, vf, v_prev, u, side)


@njit(cache=True)
def _active_sum(w, off, m, a, b, r, p, kr, g1, up):  # pragma: no cover - compiled
    """``a`` times the weights of the operators ``off .. off + m - 1`` that move with the
    input at envelope value ``g = a u + b`` (passed as ``b``): loading ``g - r >= w``,
    unloading ``g + kr r <= min(g1 + r, w)``."""
    acc = 0.0
    for i in range(off, off + m):
        if up:
            if b - r[i] >= w[i]:
                acc += p[i]
        elif b + kr * r[i] <= min(g1 + r[i], w[i]):
            acc += p[i]
    return a * acc


@njit(cache=True)
def _slope(kind, fam, w, c, r, p, kappa, vf, v_prev, u, side):  # pragma: no cover - compiled
    """A slope (d output / d input) of family ``fam``'s output after one step to ``u``
    on a loading or unloading side: the output is piecewise linear in ``u``, convex
    when loading and concave when unloading (the envelopes are straight lines), and
    this is the slope of the piece the moving operators at ``u`` define (one of the
    two at a kink: a sub- or supergradient, which is what :func:`_root`'s Newton step
    needs)."""
    if kind == KIND_AGPI:
        m = p.size // 2
        if u > 0.0 or (u == 0.0 and side == SIDE_DOWN):
            sp = _side(max(v_prev, 0.0), u, False)
            if sp == SIDE_UP:
                return _active_sum(w, 0, m, c[0], c[0] * u + c[1], r, p, 1.0, np.inf, True)
            if sp == SIDE_DOWN:
                return _active_sum(w, 0, m, c[2], c[2] * u + c[3], r, p, 1.0, np.inf, False)
            return 0.0
        un = -u
        sn = _side(max(-v_prev, 0.0), un, False)
        if sn == SIDE_UP:  # d(-Y_n(-u))/du = Y_n'(un)
            return _active_sum(w, m, m, c[4], c[4] * un + c[5], r, p, 1.0, np.inf, True)
        if sn == SIDE_DOWN:
            return _active_sum(w, m, m, c[6], c[6] * un + c[7], r, p, 1.0, np.inf, False)
        return 0.0
    m = p.size
    if side == SIDE_UP:
        return _active_sum(w, 0, m, c[0], c[0] * u + c[1], r, p, 1.0, np.inf, True)
    g1 = np.inf
    if kind == KIND_EGPI_C:
        if u > vf:
            a, b, kr = c[2], c[3], 1.0
        else:
            a, b, kr = c[4], c[5], kappa
        if v_prev > vf >= u:
            g1 = c[2] * vf + c[3]
    elif fam == 1:
        a, b, kr = c[4], c[5], kappa
    else:
        a, b, kr = c[2], c[3], 1.0
    return _active_sum(w, 0, m, a, a * u + b, r, p, kr, g1, False)


@njit(cache=True)
def _narrowed(x, fx, target, lo, flo, hi, fhi):  # pragma: no cover
    """The bracket ``(lo, flo, hi, fhi)`` (ends and their outputs) narrowed by a point
    ``x`` inside it whose output ``fx`` is not the target: it replaces the end on its
    side of the target."""
    if fx < target:
        return x, fx, hi, fhi
    return lo, flo, x, fx


#: Newton steps :func:`_root` tries before regula falsi
NEWTON_STEPS = 16


@njit(cache=True)
def _root(
    kind, fam, w, scratch, c, r, p, kappa, vf, v_prev, side, lo, hi, target
):  # pragma: no cover
    """Input in [lo, hi] where the (nondecreasing) family output meets ``target``:
    the nearer end when the target is outside the range of the region. Returns (input,
    the family output there).

    Loading and unloading sides: Newton steps on the piecewise linear output (convex
    when loading, from ``hi``; concave when unloading, from ``lo``): each lands on the
    root of the piece it starts from, so it ends on the root's piece exactly, after as
    many steps as pieces crossed. Any step that leaves the bracket ends them; then (and
    on the initial step) safeguarded regula falsi on the bracket."""
    flo = _family(kind, fam, w, scratch, c, r, p, kappa, vf, v_prev, lo, side)
    if target <= flo:
        return lo, flo
    fhi = _family(kind, fam, w, scratch, c, r, p, kappa, vf, v_prev, hi, side)
    if target >= fhi:
        return hi, fhi
    tol_y = 1e-12 * max(1.0, abs(target))
    if side == SIDE_UP or side == SIDE_DOWN:
        if side == SIDE_UP:
            x, fx = hi, fhi
        else:
            x, fx = lo, flo
        for _ in range(NEWTON_STEPS):
            s = _slope(kind, fam, w, c, r, p, kappa, vf, v_prev, x, side)
            if not s > 0.0:
                break
            xn = x - (fx - target) / s
            if not (lo < xn < hi):
                break
            fx = _family(kind, fam, w, scratch, c, r, p, kappa, vf, v_prev, xn, side)
            x = xn
            if abs(fx - target) <= tol_y:
                return x, fx
            lo, flo, hi, fhi = _narrowed(x, fx, target, lo, flo, hi, fhi)
    bisect = False
    x = lo
    fx = flo
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
        fx = _family(kind, fam, w, scratch, c, r, p, kappa, vf, v_prev, x, side)
        if abs(fx - target) <= tol_y:
            return x, fx
        lo, flo, hi, fhi = _narrowed(x, fx, target, lo, flo, hi, fhi)
        bisect = (hi - lo) > 0.5 * width
    if abs(flo - target) <= abs(fhi - target):
        return lo, flo
    return hi, fhi


@njit(cache=True)
def _choose(xs, errs, keep, nc, v_prev, tk, y_prev, init, tol_deg):  # pragma: no cover
    """Pick among candidate inputs ``xs[:nc]`` (|errors| ``errs``; ``keep``: the
    candidate does not reverse ``v'``). Returns (input, |error|).

    Smallest |error| first. Among candidates that all meet the target (several inputs
    do, e.g. on both sides of an EGPI output switch): keep the motion direction if
    possible, then the smallest move, which changes the operator states least; this
    also keeps the paper EGPI's inverse from alternating between its two families from
    one sample to the next. Among candidates that equally miss it (a flat dead zone):
    the largest move toward the target, which is what eventually reaches it under a
    rate limit. The initial sample prefers the smaller input. "Meets" means within
    ``tol_deg`` (at least 1e-10 relative).
    """
    tol = max(tol_deg, 1e-10 * max(1.0, abs(tk)))
    best_e = np.inf
    for i in range(nc):
        best_e = min(best_e, errs[i])
    met = best_e <= tol
    lim = tol if met else best_e + 1e-12 * max(1.0, best_e)
    bi = -1
    b_keep = False
    b_score = -np.inf
    for i in range(nc):
        if errs[i] > lim:
            continue
        x = xs[i]
        if init:
            score = -x
        elif met or tk == y_prev:
            score = -abs(x - v_prev)
        elif tk < y_prev:
            score = v_prev - x
        else:
            score = x - v_prev
        kp = keep[i] and met
        if bi < 0 or (kp and not b_keep) or (kp == b_keep and score > b_score):
            bi, b_keep, b_score = i, kp, score
    return xs[bi], errs[bi]


#: Samples per compiled call of :func:`invert` (about 0.1 s of work): a Ctrl-C is
#: acted on between two calls (i2ris_calib/interrupts.py).
CHUNK = 1 << 15

# invert's state between chunks, in one float array (``STATE_SIZE`` values)
_DSTATE, _ANCHOR, _V_PREV, _Y_PREV, _INIT, _T_MOVE = range(6)
STATE_SIZE = 6


def invert(
    kind, c, r, p, kappa, vf, db, target, t, lo, hi, max_rate, quantum, v_init, has_init, tol_deg,
    chunk=CHUNK, hold=None, first_free=False, start_state=None, resume=None,
):  # fmt: skip
    """Invert the model on ``target`` sample by sample.

    The samples are inverted ``chunk`` at a time by compiled calls that carry the
    operator and ``v'`` states from one to the next (the result does not depend on
    ``chunk``) and return nothing: a Ctrl-C during one is raised in Python right after
    it, never inside numba's conversion of returned arrays (i2ris_calib/interrupts.py).

    Parameters
    ----------
    kind : int
        ``KIND_GPI``, ``KIND_EGPI``, ``KIND_EGPI_C`` or ``KIND_AGPI``.
    c : ndarray, shape (6,)
        Envelope coefficients a1..a6 (``KIND_AGPI``: shape (9,), see there).
    r, p : ndarray, shape (m,)
        Thresholds and weights.
    kappa, vf, db : float
        Stage-2 regulator, flag point, ``v'`` dead band (input unit).
    target : ndarray, shape (n,)
        Desired output (deg).
    t : ndarray, shape (n,)
        Sample times (s) (only used with a rate limit).
    lo, hi : float
        Allowed input range.
    max_rate : float
        Largest |input change| per second; ``inf`` for none.
    quantum : float
        Input resolution (1 = whole counts); 0 = real-valued commands.
    v_init : float
        Input before the first target sample (used when ``has_init``).
    has_init : bool
        True: the state starts at ``v_init`` and the first sample is an ordinary step
        (rate limited); False: the first command itself sets the initial state.
    tol_deg : float
        An output within ``tol_deg`` of the target counts as meeting it (choice among
        inputs, status); at least 1e-10 relative.
    chunk : int
        Samples per compiled call.
    hold : ndarray of bool, shape (n,), optional
        Samples where the previous command is held whatever the inverse says (the
        spike repair of :func:`~i2ris_calib.compensation.inverse.compensate`); the
        sample is still searched for its status, and a held sample whose output misses
        the target by more than ``tol_deg`` is ``STATUS_GAP`` at least.
    first_free : bool
        With ``has_init``: the first step is not rate limited (the caller sends a
        rate-limited entry ramp from ``v_init`` before it: a monotone ramp leaves the
        same operator state as one step).
    start_state : (ndarray (2, m), ndarray (STATE_SIZE,)), optional
        Start from this state (operator states ``w`` and ``state`` as :func:`start`
        and :func:`advance` leave them, e.g. after a command history) instead of
        ``v_init`` / ``has_init`` (then ignored, except ``first_free`` needs
        ``has_init``); copied, not changed.
    resume : Resume, optional
        Checkpoints of an earlier call on the same arguments but ``hold`` (filled by
        every call given one; ``resume.changed``: the samples whose ``hold`` changed
        since): only what the change reaches is inverted again (:class:`Resume`; the
        spike repair of :func:`~i2ris_calib.compensation.inverse.compensate`); the
        results are those of a whole inversion.

    Rate limit with whole counts: when ``max_rate`` allows less than one ``quantum``
    per sample, one quantum may move once ``max_rate`` times the time since the last
    move reaches it (the command would otherwise never move).

    Returns
    -------
    u : ndarray, shape (n,)
        Commands (quantised when ``quantum > 0``).
    u_real : ndarray, shape (n,)
        The best real-valued input at each sample (from the state the quantised
        commands left).
    y : ndarray, shape (n,)
        Model output for ``u`` (deg).
    status : ndarray of int8, shape (n,)
        ``STATUS_*`` of the real-valued best (0 = target reached).
    """
    target = np.ascontiguousarray(target, dtype=float)
    t = np.ascontiguousarray(t, dtype=float)
    c, r, p = (np.ascontiguousarray(a, dtype=float) for a in (c, r, p))
    n = target.size
    kind, kappa, vf, db = int(kind), float(kappa), float(vf), float(db)
    lo, hi, max_rate, quantum, tol_deg = (float(x) for x in (lo, hi, max_rate, quantum, tol_deg))
    hold = np.zeros(n, np.bool_) if hold is None else np.ascontiguousarray(hold, dtype=np.bool_)
    model = (kind, c, r, p, kappa, vf, db)
    w, state = _initial_state(model, v_init, has_init, start_state)
    state[_T_MOVE] = (t[0] if n else 0.0) - (t[1] - t[0] if n > 1 else 1.0)
    run = _ChunkRun(
        (*model, target, t, lo, hi, max_rate, quantum, tol_deg),
        (np.empty(n), np.empty(n), np.empty(n), np.zeros(n, dtype=np.int8)),
        hold,
        bool(first_free),
    )
    step = max(1, int(chunk))
    if resume is None:
        for k0 in range(0, n, step):
            run(k0, min(n, k0 + step), w, state)
        return run.outs
    return _resumed(run, n, min(step, RESUME_GRID), w, state, resume)


def _initial_state(model, v_init, has_init, start_state) -> tuple[np.ndarray, np.ndarray]:
    """(operator states ``w`` (2, m), ``state`` (STATE_SIZE,)) to invert from: a copy of
    ``start_state``, else the model's initial state at ``v_init`` (:func:`start`)."""
    p = model[3]
    if start_state is not None:
        w = np.array(start_state[0], dtype=float).reshape(2, p.size)
        return w, np.array(start_state[1], dtype=float)[:STATE_SIZE].copy()
    w = np.zeros((2, p.size))
    state = np.zeros(STATE_SIZE)
    start(*model, float(v_init), bool(has_init), w, state)
    return w, state


class _ChunkRun:
    """One :func:`invert` call's fixed arguments and outputs (``outs``: u, u_real, y,
    status, shape (n,) each); calling it inverts samples [k0, k1) from ``w``/``state``
    (updated in place) by one compiled :func:`_invert_chunk` call."""

    def __init__(self, args: tuple, outs: tuple, hold: np.ndarray, first_free: bool):
        self.args, self.outs, self.hold, self.first_free = args, outs, hold, first_free

    def __call__(self, k0: int, k1: int, w: np.ndarray, state: np.ndarray) -> None:
        _invert_chunk(*self.args, k0, k1, w, state, *self.outs, self.hold, self.first_free)


def _resumed(run: _ChunkRun, n: int, step: int, w, state, resume: Resume):
    """:func:`invert` with checkpoints every ``step`` samples: where a checkpoint of
    ``resume`` holds this call's state, the earlier results are copied up to the next
    changed ``hold`` sample instead of inverted again; ``resume`` then holds this call's
    checkpoints and results."""
    old, old_res = resume.states, resume.results
    valid = old_res is not None and resume.step == step and old_res[0].size == n
    changed = np.sort(np.asarray(resume.changed, dtype=np.int64)) if valid else None
    new_states: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    k0 = 0
    while k0 < n:
        if valid and k0 in old and _same(old[k0], w, state):
            # from here the earlier call's results hold until the next changed sample
            j = np.searchsorted(changed, k0)
            k1 = min(n, (int(changed[j]) // step) * step if j < changed.size else n)
            if k1 > k0:
                for a_new, a_old in zip(run.outs, old_res, strict=True):
                    a_new[k0:k1] = a_old[k0:k1]
                for kk in range(k0, k1, step):
                    new_states[kk] = old[kk]
                if k1 >= n:
                    break
                w, state = (a.copy() for a in old[k1])
                k0 = k1
                continue
        new_states[k0] = (w.copy(), state.copy())
        run(k0, min(n, k0 + step), w, state)
        k0 += step
    resume.states, resume.results, resume.step = new_states, run.outs, step
    resume.changed = np.zeros(0, dtype=np.int64)
    return run.outs


def _same(saved, w, state) -> bool:
    """True when the state (``w``, ``state``) is exactly the ``saved`` one."""
    return bool(np.array_equal(saved[0], w) and np.array_equal(saved[1], state))


#: Samples between the checkpoints of a :class:`Resume`
RESUME_GRID = 4096


class Resume:
    """Checkpoints of :func:`invert` for a re-inversion with a few changed ``hold``
    samples (the spike repair): the state at every :data:`RESUME_GRID` samples and the
    results of the last call; ``changed``: the samples whose ``hold`` changed since.
    The next call re-inverts the grid cells from the first changed sample until its
    state is again exactly the last call's at a grid point, copies the last call's
    results up to the next changed sample's cell, and so on: the same results as a
    whole inversion, for the cost of the cells the change reaches."""

    def __init__(self) -> None:
        self.states: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.results: tuple[np.ndarray, ...] | None = None
        self.step = 0
        self.changed = np.zeros(0, dtype=np.int64)


@njit(cache=True)
def start(kind, c, r, p, kappa, vf, db, v_init, has_init, w, state):  # pragma: no cover
    """The state before the first sample, written to ``w`` (2, m) (operator states)
    and ``state`` (shape (>= :data:`STATE_SIZE`,): ``v'`` direction and anchor,
    previous input and output, whether the first command sets the initial state, time
    of the last move): with ``has_init`` the model's initial state at rest at
    ``v_init``, else the first command sets it (:func:`invert`)."""
    state[_DSTATE] = 1.0
    state[_ANCHOR] = 0.0
    state[_V_PREV] = 0.0
    state[_Y_PREV] = 0.0
    state[_INIT] = 1.0
    state[_T_MOVE] = 0.0
    if has_init:
        n_fam = 2 if kind == KIND_EGPI else 1
        for f in range(n_fam):
            _family(kind, f, w[f], w[f], c, r, p, kappa, vf, 0.0, v_init, SIDE_INIT)
        dstate, anchor = _direction(1, 0.0, v_init, db, True)
        fam = _select(kind, 1, 0.0, v_init, db, vf, True)
        state[_DSTATE] = dstate
        state[_ANCHOR] = anchor
        state[_V_PREV] = v_init
        state[_Y_PREV] = _shown(kind, w, fam, c, p)
        state[_INIT] = 0.0


@njit(cache=True)
def _update(kind, c, r, p, kappa, vf, db, u, w, w_new, state):  # pragma: no cover
    """The state update of one input ``u`` (the forward recursion): every operator
    family, ``v'``, previous input and output (``w`` and ``state`` in place; ``w_new``
    (2, m) work space). Returns the model output after ``u`` (deg). The one update
    :func:`_step` (after choosing a command) and :func:`advance` apply."""
    m = p.size
    n_fam = 2 if kind == KIND_EGPI else 1
    dstate = int(state[_DSTATE])
    anchor = state[_ANCHOR]
    v_prev = state[_V_PREV]
    init = state[_INIT] != 0.0
    side = _side(v_prev, u, init)
    for f in range(n_fam):
        _family(kind, f, w[f], w_new[f], c, r, p, kappa, vf, v_prev, u, side)
        for i in range(m):
            w[f, i] = w_new[f, i]
    fam = _select(kind, dstate, anchor, u, db, vf, init)
    dstate, anchor = _direction(dstate, anchor, u, db, init)
    y_new = _shown(kind, w, fam, c, p)
    state[_DSTATE] = dstate
    state[_ANCHOR] = anchor
    state[_V_PREV] = u
    state[_Y_PREV] = y_new
    state[_INIT] = 0.0
    return y_new


@njit(cache=True)
def advance(kind, c, r, p, kappa, vf, db, v, w, state):  # pragma: no cover - compiled
    """Carry the state (``w`` (2, m), ``state`` as :func:`start` writes them; in
    place) through the inputs ``v`` (shape (h,)) already sent: :func:`_update` per
    input, the update the inverse applies after choosing a command. Returns the model
    output after the last one (the previous output for an empty ``v``). The time of
    the last move is left to the caller."""
    w_new = np.empty((2, p.size))
    y = state[_Y_PREV]
    for k in range(v.size):
        y = _update(kind, c, r, p, kappa, vf, db, v[k], w, w_new, state)
    return y


@njit(cache=True)
def _invert_chunk(
    kind, c, r, p, kappa, vf, db, target, t, lo, hi, max_rate, quantum, tol_deg,
    k0, k1, w, state, u_out, u_real, y_out, status, hold, first_free,
):  # pragma: no cover - compiled  # fmt: skip
    """Invert samples ``k0 .. k1 - 1`` from the state in ``w`` and ``state`` (updated in
    place), writing ``u_out``, ``u_real``, ``y_out`` and ``status`` there; returns
    nothing (see :func:`invert`). Each sample is one :func:`_step`, the step the online
    compensator (:func:`step_one`) takes too."""
    n = target.size
    m = p.size
    w_new = np.zeros((2, m))
    scratch = np.empty(m)
    buf = np.empty(40)
    keep = np.empty(16, dtype=np.bool_)
    dt0 = t[1] - t[0] if n > 1 else 1.0
    for k in range(k0, k1):
        dt = t[k] - t[k - 1] if k > 0 else dt0
        free = k == 0 and first_free
        u, ur, y, st = _step(
            kind, c, r, p, kappa, vf, db, target[k], t[k], dt, lo, hi, max_rate, quantum,
            tol_deg, hold[k], free, w, w_new, scratch, buf, keep, state,
        )  # fmt: skip
        u_out[k] = u
        u_real[k] = ur
        y_out[k] = y
        status[k] = st


# --------------------------------------------------------------------------- online
# ``prm`` (parameters) and ``mem`` (state) of one axis of the online compensator, flat
# float arrays (cheap to pass to a compiled call; :func:`pack`):
#   prm = (len(c), M, kappa, v_f, dead band, lo, hi, max_rate, quantum, tol_deg, Mc,
#          sign, c, r, p, [cc (9), cr (Mc), cp (Mc)])
#   mem = (w (2 M, row-major), state (STATE_SIZE), time of the previous command (s),
#          out (OUT_SIZE), [wc (2 Mc), cstate (STATE_SIZE)])
# M = len(p); Mc = len(cp), 0 for an axis without coupling; cc, cr, cp the coupling's
# two-tendon GPI on the other motor's signed counts (KIND_AGPI, its theta0 0, its
# signs folded into cp); wc, cstate its state (as w, state; the other motor's last
# counts in cstate[_V_PREV]); sign: robot counts = sign x model input.
#   out = (command, best real-valued input, model output incl. coupling, status,
#          coupling (deg), Gauss-Seidel rounds of a joint step (-1: not settled))
PRM_HEAD = 12
OUT_SIZE = 6


@njit(cache=True)
def _coupling_step(prm, mem, vo):  # pragma: no cover - compiled
    """Advance an axis's coupling state with the other motor's signed counts ``vo``;
    returns the coupling (deg); 0 for an axis without coupling."""
    nc = int(prm[0])
    m = int(prm[1])
    mc = int(prm[10])
    if mc == 0:
        return 0.0
    o = PRM_HEAD + nc + 2 * m
    cc = prm[o : o + 9]
    cr = prm[o + 9 : o + 9 + mc]
    cp = prm[o + 9 + mc : o + 9 + 2 * mc]
    q = 2 * m + STATE_SIZE + 1 + OUT_SIZE
    wc = mem[q : q + 2 * mc].reshape((2, mc))
    cstate = mem[q + 2 * mc : q + 2 * mc + STATE_SIZE]
    return _update(KIND_AGPI, cc, cr, cp, 1.0, np.inf, 0.0, vo, wc, np.empty((2, mc)), cstate)


@njit(cache=True)
def step_one(kind, prm, mem, target, dt, vo):  # pragma: no cover - compiled
    """One online step (:class:`~i2ris_calib.compensation.online.Compensator`): the
    batch's :func:`_step` on one target sample (deg, model convention), ``dt`` seconds
    after the previous one, on the packed arrays of :func:`pack` (``mem`` updated in
    place, results in its ``out``). A coupled axis first advances its coupling with the
    other motor's signed counts ``vo`` at this sample and inverts its own tendons on the
    target less the coupling (as the batch does); ``vo`` is ignored otherwise."""
    nc = int(prm[0])
    m = int(prm[1])
    c = prm[PRM_HEAD : PRM_HEAD + nc]
    r = prm[PRM_HEAD + nc : PRM_HEAD + nc + m]
    p = prm[PRM_HEAD + nc + m : PRM_HEAD + nc + 2 * m]
    w = mem[: 2 * m].reshape((2, m))
    state = mem[2 * m : 2 * m + STATE_SIZE + 1]
    yc = _coupling_step(prm, mem, vo)
    w_new = np.empty((2, m))
    scratch = np.empty(m)
    buf = np.empty(40)
    keep = np.empty(16, dtype=np.bool_)
    t_k = state[STATE_SIZE] + dt
    u, ur, y, st = _step(
        kind, c, r, p, prm[2], prm[3], prm[4], target - yc, t_k, dt, prm[5], prm[6], prm[7],
        prm[8], prm[9], False, False, w, w_new, scratch, buf, keep, state,
    )  # fmt: skip
    state[STATE_SIZE] = t_k
    o = 2 * m + STATE_SIZE + 1
    mem[o] = u
    mem[o + 1] = ur
    mem[o + 2] = y + yc
    mem[o + 3] = st
    mem[o + 4] = yc
    mem[o + 5] = 1.0


@njit(cache=True)
def _last_counts(prm, mem):  # pragma: no cover - compiled
    """The axis's last command in signed counts (robot sign)."""
    return prm[11] * mem[2 * int(prm[1]) + _V_PREV]


@njit(cache=True)
def step_pair(ka, prm_a, mem_a, kb, prm_b, mem_b, ta, tb, dt, rounds):  # pragma: no cover
    """One online step of two axes whose models read each other's motor (at least one
    coupled): the two commands solved jointly at this sample by Gauss-Seidel. Axis a is
    stepped (:func:`step_one`, from the state before this sample) given b's last
    command, then b given a's command, then a again given b's new one, and so on, until
    a step repeats the command it had (a fixed point: each command is then the batch's
    inverse given the other motor's command sent) or after ``2 rounds`` steps. An
    uncoupled axis is solved first (one step each). Unsettled: the last commands are
    sent; the axis stepped before the last has its coupling advanced with the command
    the other axis sends (the model state stays the robot's) and ``out`` rounds -1.
    Settled: ``out`` rounds = the steps taken."""
    if prm_b[10] == 0:  # b does not read a: b first, then a with b's command
        step_one(kb, prm_b, mem_b, tb, dt, 0.0)
        step_one(ka, prm_a, mem_a, ta, dt, _last_counts(prm_b, mem_b))
        return
    if prm_a[10] == 0:
        step_one(ka, prm_a, mem_a, ta, dt, 0.0)
        step_one(kb, prm_b, mem_b, tb, dt, _last_counts(prm_a, mem_a))
        return
    save_a = mem_a.copy()
    save_b = mem_b.copy()
    ub = _last_counts(prm_b, mem_b)
    step_one(ka, prm_a, mem_a, ta, dt, ub)
    ua = _last_counts(prm_a, mem_a)
    n = 1
    done = False
    last_a = True  # the axis stepped last
    while n < 2 * rounds:
        if last_a:
            if n > 1:
                mem_b[:] = save_b
            step_one(kb, prm_b, mem_b, tb, dt, ua)
            u_new = _last_counts(prm_b, mem_b)
            done = u_new == ub
            ub = u_new
        else:
            mem_a[:] = save_a
            step_one(ka, prm_a, mem_a, ta, dt, ub)
            u_new = _last_counts(prm_a, mem_a)
            done = u_new == ua
            ua = u_new
        n += 1
        last_a = not last_a
        if done:
            break
    oa = 2 * int(prm_a[1]) + STATE_SIZE + 1
    ob = 2 * int(prm_b[1]) + STATE_SIZE + 1
    if done:
        mem_a[oa + 5] = n
        mem_b[ob + 5] = n
        return
    # not settled: the axis stepped before the last follows the other's command sent
    if last_a:
        _recouple(prm_b, mem_b, save_b, ua)
    else:
        _recouple(prm_a, mem_a, save_a, ub)
    mem_a[oa + 5] = -1.0
    mem_b[ob + 5] = -1.0


@njit(cache=True)
def _recouple(prm, mem, save, vo):  # pragma: no cover - compiled
    """Redo an axis's coupling step of this sample with the other motor's counts ``vo``
    (its coupling state restored from ``save``), its output in ``out`` updated."""
    m = int(prm[1])
    mc = int(prm[10])
    o = 2 * m + STATE_SIZE + 1
    q = o + OUT_SIZE
    mem[q : q + 2 * mc + STATE_SIZE] = save[q : q + 2 * mc + STATE_SIZE]
    yc = _coupling_step(prm, mem, vo)
    mem[o + 2] = mem[o + 2] - mem[o + 4] + yc
    mem[o + 4] = yc


def pack(c, r, p, cfg, sign=1.0, coupling=None):
    """(``prm``, ``mem``) of :func:`step_one` for kernel arrays ``c``, ``r``, ``p``,
    ``cfg`` = (kappa, v_f, dead band, lo, hi, max_rate, quantum, tol_deg), ``sign``
    and ``coupling`` = (cc, cr, cp) or None (layout above); ``mem`` zeroed."""
    c, r, p, cfg = (np.asarray(a, dtype=float).ravel() for a in (c, r, p, cfg))
    parts = [[c.size, p.size], cfg, [0.0 if coupling is None else len(coupling[2]), sign], c, r, p]
    mc = 0
    if coupling is not None:
        cc, cr, cp = (np.asarray(a, dtype=float).ravel() for a in coupling)
        mc = cp.size
        parts += [cc, cr, cp]
    prm = np.concatenate([np.asarray(x, dtype=float) for x in parts])
    mem = np.zeros(2 * p.size + STATE_SIZE + 1 + OUT_SIZE + (2 * mc + STATE_SIZE if mc else 0))
    return prm, mem


def views(prm, mem):
    """Named views into an axis's ``mem``: (w (2, M), state (STATE_SIZE + 1: the last
    is the time), out (OUT_SIZE,), wc (2, Mc) or None, cstate or None)."""
    m, mc = int(prm[1]), int(prm[10])
    o = 2 * m + STATE_SIZE + 1
    w = mem[: 2 * m].reshape(2, m)
    state = mem[2 * m : o]
    out = mem[o : o + OUT_SIZE]
    if not mc:
        return w, state, out, None, None
    q = o + OUT_SIZE
    wc = mem[q : q + 2 * mc].reshape(2, mc)
    return w, state, out, wc, mem[q + 2 * mc : q + 2 * mc + STATE_SIZE]


@njit(cache=True)
def _step(
    kind, c, r, p, kappa, vf, db, tk, t_k, dt, lo, hi, max_rate, quantum, tol_deg,
    hold_k, free, w, w_new, scratch, buf, cand_keep, state,
):  # pragma: no cover - compiled  # fmt: skip
    """Invert one target sample ``tk`` (deg) at time ``t_k`` (s), ``dt`` after the
    previous one, from the state ``w`` / ``state`` (updated in place): returns
    (command, best real-valued input, model output, status). ``hold_k``: hold the
    previous command; ``free``: no rate limit on this step. ``w_new``, ``scratch``,
    ``buf`` (40,), ``cand_keep`` (16,): work space."""
    dstate = int(state[_DSTATE])
    anchor = state[_ANCHOR]
    v_prev = state[_V_PREV]
    y_prev = state[_Y_PREV]
    init = state[_INIT] != 0.0
    cand_x = buf[8:24]
    cand_e = buf[24:40]
    a_lim, b_lim = _rate_window(lo, hi, v_prev, max_rate, dt, free, quantum, t_k - state[_T_MOVE])
    if init:
        a_lim, b_lim = lo, hi
    # the search spans the whole input range; a rate limit then slews the command
    # toward the unconstrained inverse (through dead zones and output switches that
    # a myopic choice inside the rate window would never cross)
    qa, qb = _on_grid(a_lim, b_lim, quantum)
    qlo, qhi = _on_grid(lo, hi, quantum)
    nc = _hold_candidate(v_prev, y_prev, tk, init, cand_x, cand_e, cand_keep)
    nb = _breakpoints(kind, vf, anchor, db, init, buf[0:3])
    for side_i in range(2):
        ok, s_lo, s_hi, side = _side_range(side_i, kind, lo, hi, v_prev, y_prev, tk, init)
        if not ok:
            continue
        ne = _region_edges(s_lo, s_hi, buf[0:3], nb, buf[3:8])
        nc = _side_candidates(
            kind, c, r, p, kappa, vf, db, dstate, anchor, v_prev, init, tk, side, buf[3:8], ne,
            w, scratch, cand_x, cand_e, cand_keep, nc,
        )  # fmt: skip
    best_r, best_r_err = _choose(cand_x, cand_e, cand_keep, nc, v_prev, tk, y_prev, init, tol_deg)
    best_q = best_r
    if quantum > 0:
        best_q = _whole_count_choice(
            kind, c, r, p, kappa, vf, db, dstate, anchor, v_prev, y_prev, init, tk, tol_deg,
            best_r, quantum, qlo, qhi, w, scratch, cand_x, cand_e, cand_keep,
        )  # fmt: skip
    best_r, best_q, stat = _limited(
        kind, c, r, p, kappa, vf, db, dstate, anchor, v_prev, init, tk, tol_deg, lo, hi,
        (a_lim, b_lim, qa, qb), best_r, best_r_err, best_q, hold_k, w, scratch,
    )  # fmt: skip
    # apply the chosen command (the forward recursion, as :func:`advance`)
    u = best_q
    y_new = _update(kind, c, r, p, kappa, vf, db, u, w, w_new, state)
    if u != v_prev or init:
        state[_T_MOVE] = t_k
    return u, best_r, y_new, stat


@njit(cache=True)
def _limited(
    kind, c, r, p, kappa, vf, db, dstate, anchor, v_prev, init, tk, tol_deg, lo, hi,
    window, best_r, best_r_err, best_q, hold_k, w, scratch,
):  # pragma: no cover - compiled  # fmt: skip
    """(real-valued input, command, status) of :func:`_step` after the rate window
    ``window`` = (a_lim, b_lim, qa, qb) (real and on the command grid) and a hold:
    the status is that of the real-valued best unconstrained by the rate limit
    (unreached), else ``STATUS_RATE`` when the clamp leaves the target missed, else
    ``STATUS_GAP`` when a held command misses it."""
    a_lim, b_lim, qa, qb = window
    # status of the real-valued best (unconstrained by the rate limit)
    tol = max(tol_deg, 1e-10 * max(1.0, abs(tk)))
    stat = STATUS_OK
    if best_r_err > tol:
        y_best = _exact(
            kind, w, scratch, c, r, p, kappa, vf, db, dstate, anchor, v_prev, best_r, init
        )
        stat = _unreached_status(tk, y_best, best_r, lo, hi)
    if best_r > b_lim or best_r < a_lim:
        best_r = min(max(best_r, a_lim), b_lim)
        best_q = qb if best_q > qb else qa if best_q < qa else best_q
        if stat == STATUS_OK:
            y_c = _exact(
                kind, w, scratch, c, r, p, kappa, vf, db, dstate, anchor, v_prev, best_r, init
            )
            if abs(y_c - tk) > tol:
                stat = STATUS_RATE
    elif best_q > qb or best_q < qa:
        best_q = qb if best_q > qb else qa
    if hold_k and not init:
        best_q = v_prev
        y_f = _exact(kind, w, scratch, c, r, p, kappa, vf, db, dstate, anchor, v_prev, best_q, init)
        if abs(y_f - tk) > tol and stat == STATUS_OK:
            stat = STATUS_GAP
    return best_r, best_q, stat


@njit(cache=True)
def _rate_window(lo, hi, v_prev, max_rate, dt, free, quantum, since_move):  # pragma: no cover
    """(lowest, highest) input reachable from ``v_prev`` in ``dt`` s at ``max_rate``
    (``free``: no limit), inside [lo, hi] but always including ``v_prev``. Less than a
    ``quantum`` per sample: one quantum once ``since_move`` (s since the last move)
    allows it."""
    step = max_rate * dt
    if free:
        step = np.inf
    if not np.isfinite(step):
        step = np.inf
    elif 0 < quantum and step < quantum:
        if max_rate * since_move >= quantum * (1.0 - 1e-9):
            step = quantum
    a_lim = max(lo, v_prev - step)
    b_lim = min(hi, v_prev + step)
    return min(a_lim, v_prev), max(b_lim, v_prev)


@njit(cache=True)
def _on_grid(a, b, quantum):  # pragma: no cover - compiled
    """(first, last) multiple of ``quantum`` inside [a, b]; (a, b) when ``quantum`` is 0."""
    if quantum > 0:
        return np.ceil(a / quantum - 1e-9) * quantum, np.floor(b / quantum + 1e-9) * quantum
    return a, b


@njit(cache=True)
def _hold_candidate(v_prev, y_prev, tk, init, cand_x, cand_e, cand_keep):  # pragma: no cover
    """Holding the previous input as candidate 0 (none from the initial state); returns
    the number of candidates."""
    if init:
        return 0
    cand_x[0] = v_prev
    cand_e[0] = abs(y_prev - tk)
    cand_keep[0] = True
    return 1


@njit(cache=True)
def _breakpoints(kind, vf, anchor, db, init, bps):  # pragma: no cover - compiled
    """Inputs where the shown family (or the initial boundary) changes, into ``bps``
    (3,); for the two-tendon GPI the kink at zero input, where the other tendon takes
    over. Returns how many."""
    if kind == KIND_EGPI and not init:
        bps[0] = vf
        bps[1] = anchor + db
        bps[2] = anchor - db
        return 3
    if kind == KIND_EGPI_C:
        bps[0] = vf
        return 1
    if kind == KIND_AGPI:
        bps[0] = 0.0
        return 1
    return 0


@njit(cache=True)
def _side_range(side_i, kind, lo, hi, v_prev, y_prev, tk, init):  # pragma: no cover
    """(searched, low end, high end, side) of search side ``side_i`` (0: up from the
    previous input, 1: down; from the initial state one side over [lo, hi]). Not
    searched: no room that way, or (but for the EGPI, whose output can switch) the
    target lies the other way."""
    if init:
        return side_i == 0, lo, hi, SIDE_INIT
    if side_i == 0:
        ok = not (hi <= v_prev) and (kind == KIND_EGPI or not (tk <= y_prev))
        return ok, v_prev, hi, SIDE_UP
    ok = not (lo >= v_prev) and (kind == KIND_EGPI or not (tk >= y_prev))
    return ok, lo, v_prev, SIDE_DOWN


@njit(cache=True)
def _region_edges(s_lo, s_hi, bps, nb, edges):  # pragma: no cover - compiled
    """The side's ends and the breakpoints strictly inside, sorted into ``edges``;
    returns how many."""
    ne = 0
    edges[ne] = s_lo
    ne += 1
    for j in range(nb):
        if s_lo < bps[j] < s_hi:
            edges[ne] = bps[j]
            ne += 1
    edges[ne] = s_hi
    ne += 1
    edges[:ne].sort()
    return ne


@njit(cache=True)
def _side_candidates(
    kind, c, r, p, kappa, vf, db, dstate, anchor, v_prev, init, tk, side, edges, ne,
    w, scratch, cand_x, cand_e, cand_keep, nc,
):  # pragma: no cover - compiled  # fmt: skip
    """One candidate per region between ``edges`` of a side: the root of the model's
    output there minus ``tk`` (or the nearest end), with its error and whether it keeps
    the motion direction; appended after ``nc``, returns the new count."""
    for j in range(ne - 1):
        e0, e1 = edges[j], edges[j + 1]
        if e1 <= e0:
            continue
        mid = 0.5 * (e0 + e1)
        fam = _select(kind, dstate, anchor, mid, db, vf, init)
        x, y = _root(kind, fam, w[fam], scratch, c, r, p, kappa, vf, v_prev, side, e0, e1, tk)
        # an open end (the previous input, a breakpoint) -> just inside the region
        eps = 1e-9 * max(1.0, abs(x))
        moved = False
        if x == e0 and not (init or (side == SIDE_DOWN and j == 0)):
            x = min(e0 + eps, mid)
            moved = True
        elif x == e1 and not (init or (side == SIDE_UP and j == ne - 2)):
            x = max(e1 - eps, mid)
            moved = True
        if moved or kind == KIND_EGPI:
            # the output the model shows there (the EGPI: maybe the other family);
            # else the root's own evaluation is that output (same family and side)
            y = _exact(kind, w, scratch, c, r, p, kappa, vf, db, dstate, anchor, v_prev, x, init)
        nc = _add_candidate(x, y, tk, dstate, anchor, db, init, cand_x, cand_e, cand_keep, nc)
    return nc


@njit(cache=True)
def _add_candidate(
    x, y, tk, dstate, anchor, db, init, cand_x, cand_e, cand_keep, nc
):  # pragma: no cover
    """Input ``x`` (output ``y``) as candidate ``nc``: its error to ``tk`` and whether it
    keeps the motion direction; returns the new count."""
    cand_x[nc] = x
    cand_e[nc] = abs(y - tk)
    d_new, _ = _direction(dstate, anchor, x, db, init)
    cand_keep[nc] = init or d_new == dstate
    return nc + 1


@njit(cache=True)
def _whole_count_choice(
    kind, c, r, p, kappa, vf, db, dstate, anchor, v_prev, y_prev, init, tk, tol_deg,
    best_r, quantum, qlo, qhi, w, scratch, cand_x, cand_e, cand_keep,
):  # pragma: no cover - compiled  # fmt: skip
    """The whole count (multiple of ``quantum`` in [qlo, qhi]) to send: the best of the
    two around the real-valued choice ``best_r`` and the hold, by :func:`_choose`."""
    nq = _hold_candidate(v_prev, y_prev, tk, init, cand_x, cand_e, cand_keep)
    for qi in range(2):
        xq = (np.floor(best_r / quantum) if qi == 0 else np.ceil(best_r / quantum)) * quantum
        xq = min(max(xq, qlo), qhi)
        yq = _exact(kind, w, scratch, c, r, p, kappa, vf, db, dstate, anchor, v_prev, xq, init)
        nq = _add_candidate(xq, yq, tk, dstate, anchor, db, init, cand_x, cand_e, cand_keep, nq)
    best_q, _ = _choose(cand_x, cand_e, cand_keep, nq, v_prev, tk, y_prev, init, tol_deg)
    return best_q


@njit(cache=True)
def _unreached_status(tk, y_best, best_r, lo, hi):  # pragma: no cover - compiled
    """Why the best input misses the target: above the reach (at the top of the range),
    below it (at the bottom), or a gap in the model's output."""
    near = 1e-6 * max(1.0, abs(best_r))
    if tk > y_best and best_r >= hi - near:
        return STATUS_ABOVE
    if tk < y_best and best_r <= lo + near:
        return STATUS_BELOW
    return STATUS_GAP
