"""Hidden-effect cases from generators written independently of the catalogue.

Nothing here imports :mod:`i2ris_calib.diagnosis` or the hysteresis models: the base
is a classical Prandtl-Ishlinskii model in its own parametrisation (thresholds in
input units, exponential weights, a linear term), each effect is coded here from
its textbook definition (not from the catalogue's formula), and the trajectories
are their own (ramps of 2-10 s to random levels, holds of 0.5-3 s between ramps,
partial returns). A catalogue form that only matches its own generator fails here.

Used by ``tests/diagnosis/test_independent_generators.py`` and
``benchmarks/bench_diagnosis.py`` (the suite of the targets).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.data.dataset import input_bands, make_dataset
from i2ris_calib.fitting.config import FitConfig

RATE_HZ = 30.0

#: Effect -> (weak, strong) strength of its own parameter (see :func:`apply_effect`).
SUITE: dict[str, tuple[float, float]] = {
    "dead_zone": (0.03, 0.07),  # break point, fraction of the largest input
    "backlash": (0.03, 0.08),  # play width, fraction of the largest input
    "rate_dependent_thresholds": (0.25, 0.6),  # s: threshold increase per unit/s of speed
    "rate_dependent_weights": (0.15, 0.35),  # weight increase at the fastest ramp speed
    "creep": (0.2, 0.4),  # fraction arriving with a 1.2 s time constant
    "creep_log": (0.015, 0.04),  # fraction of a move added per decade of time
    "time_delay": (0.15, 0.35),  # s
    "axis_coupling_angle": (0.02, 0.05),  # deg per deg of the other axis
    "axis_coupling_input": (0.015, 0.04),  # deg per 100 counts of the other tendon input
    "saturation": (0.06, 0.15),  # relative flattening at the top of the range
    "multi_stage_backlash": (0.03, 0.08),  # second stage's play, fraction of the input
    # thresholds r_i (1 + beta |v'|) (Al Janaideh, Rakheja, Su): relative threshold
    # increase at the fastest ramp speed (last, so the other cases keep their seeds)
    "rate_dependent_thresholds_scaled": (0.6, 1.5),
}

#: The catalogue name the diagnosis should give each generated effect.
EXPECTED: dict[str, str] = {
    "axis_coupling_angle": "axis_coupling",
    "axis_coupling_input": "axis_coupling",
    # the catalogue has one rate-dependent-threshold form (thresholds r_i + beta |v'|);
    # proportional thresholds r_i (1 + beta |v'|) are the same physics (thresholds that
    # widen with speed), fitted by it approximately (docs/diagnosis.md, Benchmark)
    "rate_dependent_thresholds_scaled": "rate_dependent_thresholds",
    "rate_dependent_thresholds_power": "rate_dependent_thresholds",
}


def expected_name(effect: str) -> str:
    """Catalogue name a right diagnosis gives ``effect``."""
    return EXPECTED.get(effect, effect)


@dataclass(frozen=True)
class IndependentCase:
    """One generated recording of one axis (its ``"+"`` direction: input >= 0).

    Attributes
    ----------
    t_s, v, v_other, theta_other_deg, theta_deg : ndarray, shape (n,)
        Time (s), input (counts), the other axis's input (counts) and measured
        angle (deg), this axis's measured angle (deg).
    truth_deg : ndarray, shape (n,)
        Noise-free angle with the effect; ``clean_deg`` without it.
    effect : str or None
    strength : float
    noise_deg : float
    """

    t_s: np.ndarray
    v: np.ndarray
    v_other: np.ndarray
    theta_other_deg: np.ndarray
    theta_deg: np.ndarray
    truth_deg: np.ndarray
    clean_deg: np.ndarray
    effect: str | None
    strength: float
    noise_deg: float

    @property
    def effect_rms_deg(self) -> float:
        """RMS of what the effect adds to the angle (deg)."""
        return float(np.sqrt(np.mean((self.truth_deg - self.clean_deg) ** 2)))


def trajectory(rng, v_max: float, n_moves: int = 18) -> tuple[np.ndarray, np.ndarray]:
    """Ramps of 2-10 s between random levels (every third one a partial return),
    each followed by a hold of 0.5-3 s; starts and ends at 0. Whole counts."""
    kt, kv = [0.0, 1.0], [0.0, 0.0]
    level = 0.0
    for i in range(n_moves):
        if i % 2 == 0:
            target = v_max if i in (0, n_moves - 2) else rng.uniform(0.45, 1.0) * v_max
        else:
            target = 0.0 if i % 3 != 0 else rng.uniform(0.1, 0.4) * level
        kt.append(kt[-1] + rng.uniform(2.0, 10.0))
        kv.append(target)
        kt.append(kt[-1] + rng.uniform(0.5, 3.0))
        kv.append(target)
        level = target
    kt.append(kt[-1] + rng.uniform(2.0, 10.0))
    kv.append(0.0)
    kt.append(kt[-1] + 1.5)
    kv.append(0.0)
    t = np.arange(0.0, kt[-1], 1.0 / RATE_HZ)
    return t, np.round(np.interp(t, kt, kv))


def play(v: np.ndarray, r) -> np.ndarray:
    """Play operator of half-width ``r`` (scalar or shape (n,)), initial state v[0]."""
    r = np.broadcast_to(np.asarray(r, float), v.shape)
    out = np.empty_like(v, dtype=float)
    w = float(v[0])
    for k in range(v.size):
        w = min(max(w, v[k] - r[k]), v[k] + r[k])
        out[k] = w
    return out


@dataclass(frozen=True)
class PI:
    """Classical Prandtl-Ishlinskii model: ``y = a v + sum_i w_i F_ri[v]``.

    Thresholds ``r_i = i R / m`` (counts), weights ``w_i = w exp(-r_i / rho)``.
    """

    a: float
    w: float
    R: float
    rho: float
    m: int = 12

    def radii(self) -> np.ndarray:
        return np.arange(1, self.m + 1) * self.R / self.m

    def weights(self) -> np.ndarray:
        return self.w * np.exp(-self.radii() / self.rho)

    def __call__(self, v, extra_radius=None, weight_factor=None, radius_factor=None) -> np.ndarray:
        """Output (deg); ``extra_radius`` (shape (n,)) is added to every threshold,
        ``radius_factor`` (shape (n,)) multiplies every threshold,
        ``weight_factor`` (shape (n,)) multiplies every operator weight."""
        v = np.asarray(v, float)
        y = self.a * v
        for r, w in zip(self.radii(), self.weights(), strict=True):
            rr = r if extra_radius is None else r + extra_radius
            rr = rr if radius_factor is None else rr * radius_factor
            f = play(v, rr)
            y = y + w * (f if weight_factor is None else weight_factor * f)
        return y


def random_pi(rng, v_max: float, top_deg: float) -> PI:
    """A PI whose loading curve reaches about ``top_deg`` at ``v_max``."""
    R = rng.uniform(0.15, 0.35) * v_max
    rho = rng.uniform(0.3, 1.0) * R
    share = rng.uniform(0.4, 0.7)  # share of the hysteretic operators in the slope
    slope = top_deg / v_max
    probe = PI(a=0.0, w=1.0, R=R, rho=rho)
    wsum = float(np.sum(probe.weights()))
    return PI(a=(1 - share) * slope, w=share * slope / wsum, R=R, rho=rho)


def _speed(t, v):
    return np.abs(np.gradient(v, t))


def _lagged(y, t, tau):
    out = np.empty_like(y)
    out[0] = y[0]
    for k in range(1, y.size):
        a = 1.0 - np.exp(-(t[k] - t[k - 1]) / tau)
        out[k] = out[k - 1] + a * (y[k] - out[k - 1])
    return out


def apply_effect(effect, s, rng, t, v, v_other, th_other, pi: PI, v_max: float) -> np.ndarray:
    """Noise-free angle (deg) of ``pi`` driven by ``v`` with ``effect`` of strength ``s``."""
    if effect is None:
        return pi(v)
    if effect == "dead_zone":
        return pi(np.maximum(v - s * v_max, 0.0))
    if effect == "backlash":
        return pi(play(v, 0.5 * s * v_max))
    if effect == "rate_dependent_thresholds":
        return pi(v, extra_radius=s * _speed(t, v))
    if effect == "rate_dependent_thresholds_scaled":
        # r_i(t) = r_i (1 + beta |dv/dt|), beta = s / fastest speed; a = linear, unaffected
        sp = _speed(t, v)
        return pi(v, radius_factor=1.0 + s * sp / np.max(sp))
    if effect == "rate_dependent_thresholds_power":
        # r_i(t) = r_i s (|dv/dt| / fastest)^0.5: the power form (Al Janaideh, Rakheja,
        # Su), no hysteresis at rest; not in SUITE (bench --power), linear term unaffected
        sp = _speed(t, v)
        return pi(v, radius_factor=s * np.sqrt(sp / np.max(sp)))
    if effect == "rate_dependent_weights":
        sp = _speed(t, v)
        return pi(v, weight_factor=1.0 + s * sp / np.max(sp))
    if effect == "creep":
        y = pi(v)
        return (1 - s) * y + s * _lagged(y, t, 1.2)
    if effect == "creep_log":
        y = pi(v)
        dy = np.diff(y, prepend=y[0])
        tau0 = 0.2
        kern = np.log10(1.0 + np.arange(t.size) / RATE_HZ / tau0)
        return y + s * np.convolve(dy, kern)[: t.size]
    if effect == "time_delay":
        return pi(np.interp(t - s, t, v))
    if effect == "axis_coupling_angle":
        return pi(v) + s * th_other
    if effect == "axis_coupling_input":
        return pi(v) + s * v_other / 100.0
    if effect == "saturation":
        y = pi(v)
        top = float(np.max(np.abs(y)))
        # y -> L tanh(y / L), L chosen so that the top is flattened by s (relative):
        # tanh(x) / x = 1 - s with x = top / L, by bisection
        lo, hi = 1e-6, 20.0
        for _ in range(80):
            x = 0.5 * (lo + hi)
            lo, hi = (x, hi) if np.tanh(x) / x > 1 - s else (lo, x)
        L = top / x
        return L * np.tanh(y / L)
    if effect == "multi_stage_backlash":
        # a second stage whose slack (width s v_max) is taken up while unloading
        # below a flag point and paid back when loading again
        flag = rng.uniform(0.3, 0.6) * v_max
        width = s * v_max
        u = np.empty_like(v)
        slack = 0.0
        for k in range(v.size):
            if k:
                dv = v[k] - v[k - 1]
                if dv < 0 and v[k] < flag:
                    slack = min(width, slack + min(-dv, flag - v[k]))
                elif dv > 0:
                    slack = max(0.0, slack - dv)
            u[k] = v[k] + slack
        return pi(u)
    raise ValueError(f"unknown effect {effect}")


def make_independent_case(
    seed: int,
    effect: str | None,
    strength: float = 0.0,
    noise_deg: float = 0.08,
    n_moves: int = 18,
) -> IndependentCase:
    """One case: random PI, own trajectory, the effect, white noise on both axes."""
    rng = np.random.default_rng(seed)
    v_max = rng.uniform(4000.0, 7000.0)
    t, v = trajectory(rng, v_max, n_moves)
    # the other axis: slower ramps of its own
    kt, kv = [0.0], [rng.uniform(0, 0.5) * v_max]
    while kt[-1] < t[-1]:
        kt.append(kt[-1] + rng.uniform(6.0, 15.0))
        kv.append(rng.uniform(0.0, 1.0) * v_max)
    v_other = np.round(np.interp(t, kt, kv))
    other = random_pi(rng, v_max, rng.uniform(20.0, 35.0))
    th_other_true = other(v_other)
    pi = random_pi(rng, v_max, rng.uniform(25.0, 40.0))
    clean = pi(v)
    truth = apply_effect(effect, strength, rng, t, v, v_other, th_other_true, pi, v_max)
    th_other = th_other_true + rng.normal(0.0, noise_deg, t.size)
    theta = truth + rng.normal(0.0, noise_deg, t.size)
    return IndependentCase(
        t, v, v_other, th_other, theta, truth, clean, effect, strength, noise_deg
    )


def suite(full: bool = True) -> list[tuple[str | None, float, float, int]]:
    """(effect, strength, noise_deg, seed) of the suite: every effect x (weak,
    strong) x 2 draws (noise 0.08 and 0.2 deg), plus 8 clean cases."""
    out = []
    seed = 7000
    for name, strengths in SUITE.items():
        for s in strengths:
            for noise in (0.08, 0.2):
                seed += 1
                out.append((name, s, noise, seed))
    for i in range(8):
        out.append((None, 0.0, (0.08, 0.2)[i % 2], 7900 + i))
    return out


def case_as_dataset(case: IndependentCase):
    """The ``"+"`` :class:`~i2ris_calib.data.Dataset` that ``fit`` and ``diagnose``
    would build from the case's synced CSV (bands derived, default held-out cycles)."""
    cfg = FitConfig()
    return make_dataset(
        "yaw",
        "+",
        case.t_s,
        case.v,
        case.theta_deg,
        enc_other=case.v_other,
        theta_other_deg=case.theta_other_deg,
        bands=input_bands(case.v, cfg.zero_band_counts, cfg.deadband_counts),
        holdout_fraction=cfg.holdout_fraction,
        source=f"independent case ({case.effect or 'clean'})",
    )
