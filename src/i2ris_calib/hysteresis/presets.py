"""Plausible true parameters and input trajectories for synthetic I2RIS data.

Encoder range (our choice, docs/models.md): a motion direction spans
0..``v_max_counts`` = 6000 counts at full bending (Maxon ENX 8MAG 256 pulses/rev,
x4 quadrature = 1024 counts/rev at the motor; 64:1 gear; about 0.09 output revolutions
of the tendon pulley for 30-45 deg of bending). Negative-direction datasets use the
same range on |counts|.

The I2RIS-EGPI recipe (:func:`random_i2ris_egpi_params`) produces loops like the
paper's Fig 3(a)/6: a dead zone S1 when loading starts, a soft dead zone S2 when
unloading starts (stage 1, thresholds r), a second dead zone S3 after the flag point
v_f (stage 2, thresholds kappa r), bending range 30-45 deg. Note a property of
Eq20 itself: at v_f the output switches from y1 to y2, which are generally not equal,
so the modelled unloading branch has a step at v_f.
"""

from __future__ import annotations

import numpy as np

from i2ris_calib.hysteresis.models import density, thresholds

V_MAX_COUNTS = 6000.0
DATASETS = ("yaw+", "yaw-", "pitch+", "pitch-")
# bending ranges implied by the paper's Tables 1-2 (RMSE / NRMSE), deg
PAPER_RANGES_DEG = {"yaw+": 37.0, "yaw-": 31.0, "pitch+": 35.0, "pitch-": 44.0}
_PAPER_SEEDS = {"yaw+": 11, "yaw-": 12, "pitch+": 13, "pitch-": 14}

# the 8 GPI parameters, in GPIModel order
GPI_NAMES = ("a1", "a2", "a3", "a4", "lam", "sigma", "r1", "rn")


def random_i2ris_egpi_params(
    rng: np.random.Generator,
    v_max_counts: float = V_MAX_COUNTS,
    range_deg: float | None = None,
    n: int = 30,
) -> dict[str, float]:
    """One plausible true parameter set of the I2RIS EGPI (12 values incl. ``v_f``).

    Parameters
    ----------
    rng : numpy Generator
        Source of every random choice.
    v_max_counts : float
        Full-scale input (counts) of the motion direction; input runs 0..v_max.
    range_deg : float, optional
        Bending range at full scale (deg); drawn from U(30, 45) when None.
    n : int
        Number of non-zero thresholds (n + 1 operators).

    Returns
    -------
    dict
        ``a1..a6`` (deg/count, deg), ``lam``, ``sigma`` (1/deg), ``r1``, ``rn`` (deg),
        ``kappa``, ``v_f`` (counts).
    """
    R = float(rng.uniform(30.0, 45.0)) if range_deg is None else float(range_deg)
    sigma = rng.uniform(0.02, 0.15)
    r1 = rng.uniform(0.2, 0.6)
    rn = rng.uniform(3.0, 6.0)
    r = thresholds(r1, rn, n)
    lam = rng.uniform(0.9, 1.1) / np.exp(-sigma * r).sum()
    p = density(r, lam, sigma)
    P, pr = p.sum(), (p * r).sum()
    a1 = R / (P * v_max_counts) * rng.uniform(0.97, 1.03)
    a2 = pr / P  # loading from rest starts at ~0 deg
    a3 = a1 * rng.uniform(0.9, 1.15)
    a4 = a2 - rng.uniform(0.5, 2.0)
    kappa = rng.uniform(4.0, 9.0)
    a5 = a1 * rng.uniform(2.0, 3.0)
    a6 = a4 + (1.0 - kappa) * pr / P  # both families meet at v = 0 when fully unloaded
    v_f = rng.uniform(0.62, 0.75) * v_max_counts
    keys = ("a1", "a2", "a3", "a4", "a5", "a6", "lam", "sigma", "r1", "rn", "kappa", "v_f")
    vals = (a1, a2, a3, a4, a5, a6, lam, sigma, r1, rn, kappa, v_f)
    return {k: float(x) for k, x in zip(keys, vals, strict=True)}


def paper_like_params(dataset: str, v_max_counts: float = V_MAX_COUNTS) -> dict[str, float]:
    """Fixed I2RIS-EGPI preset for ``dataset`` in ("yaw+", "yaw-", "pitch+", "pitch-").

    Same recipe as :func:`random_i2ris_egpi_params` with a fixed seed per dataset and
    the bending range the paper's Tables 1-2 imply (37, 31, 35, 44 deg). For a
    negative dataset the values map |counts| -> |deg| (the paper's convention).
    """
    if dataset not in _PAPER_SEEDS:
        raise KeyError(f"unknown dataset {dataset!r}; use one of {', '.join(DATASETS)}")
    rng = np.random.default_rng(_PAPER_SEEDS[dataset])
    return random_i2ris_egpi_params(rng, v_max_counts, PAPER_RANGES_DEG[dataset])


def gpi_values(egpi_values: dict[str, float]) -> dict[str, float]:
    """The GPI part (loading envelope and stage-1 unloading) of EGPI values."""
    return {k: egpi_values[k] for k in GPI_NAMES}


def loading_trajectory(
    rng: np.random.Generator,
    n_cycles: int = 5,
    v_max_counts: float = V_MAX_COUNTS,
    rate_hz: float = 30.0,
    speed_counts_s: float = 400.0,
    pause_s: float = 1.0,
    min_amplitude: float = 0.4,
    start_s: float = 0.0,
    n_samples: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A Fig-5-like input: ramps out and back with pauses, cycles of varying amplitude.

    Each cycle: pause at 0, ramp up at ``speed_counts_s`` to ``A * v_max``, pause,
    ramp back to 0. The first and the last cycle go to full scale; the others draw
    A from U(min_amplitude, 1). Values are whole encoder counts. With ``n_samples``
    the rate is chosen so that exactly that many samples span the trajectory
    (``rate_hz`` is then ignored).

    Returns
    -------
    t_s : ndarray, shape (n,)
        Sample times (s), uniform at ``rate_hz``.
    v : ndarray, shape (n,)
        Input (counts, integer-valued floats), >= 0.
    """
    if n_cycles < 1 or rate_hz <= 0 or speed_counts_s <= 0:
        raise ValueError("need n_cycles >= 1, rate_hz > 0, speed_counts_s > 0")
    amps = rng.uniform(min_amplitude, 1.0, n_cycles)
    amps[0] = 1.0
    amps[-1] = 1.0
    knots_t, knots_v = [0.0], [0.0]
    for a in amps:
        top = a * v_max_counts
        ramp = top / speed_counts_s
        for dt, val in ((pause_s, 0.0), (ramp, top), (pause_s, top), (ramp, 0.0)):
            knots_t.append(knots_t[-1] + dt)
            knots_v.append(val)
    knots_t.append(knots_t[-1] + pause_s)
    knots_v.append(0.0)
    if n_samples is not None:
        t = np.linspace(0.0, knots_t[-1], int(n_samples), endpoint=False)
    else:
        t = np.arange(0.0, knots_t[-1], 1.0 / rate_hz)
    v = np.round(np.interp(t, knots_t, knots_v))
    return t + start_s, v


def random_two_tendon_params(
    rng: np.random.Generator,
    v_max_counts: float = V_MAX_COUNTS,
    offset_deg: float | None = None,
    n: int = 30,
) -> dict[str, float]:
    """One plausible true parameter set of the two-tendon GPI (model kind ``"agpi"``).

    Each tendon: the GPI part of :func:`random_i2ris_egpi_params` with its own bending
    range (U(25, 45) deg at ``v_max_counts``: different gains on the two sides), put in
    the gauge ``a2 = 0`` (both envelopes shifted by ``-a2``); ``theta0`` = ``offset_deg``
    (default U(-10, 10) deg), the angle at zero input.
    """
    vals = {"theta0": float(rng.uniform(-10.0, 10.0)) if offset_deg is None else offset_deg}
    for side in ("p", "n"):
        g = gpi_values(random_i2ris_egpi_params(rng, v_max_counts, rng.uniform(25.0, 45.0), n))
        g["a4"] -= g["a2"]
        g["a2"] = 0.0
        vals |= {f"{k}_{side}": x for k, x in g.items()}
    return vals


def through_zero_trajectory(
    rng: np.random.Generator,
    n_samples: int,
    rate_hz: float = 30.0,
    v_max_counts: float = V_MAX_COUNTS,
    period_s: tuple[float, float] = (4.0, 12.0),
    hold_fraction: float = 0.1,
    burn_in_s: float = 20.0,
) -> tuple[np.ndarray, np.ndarray, int]:
    """A lab-like input driven through zero: loops of varying amplitude and period
    (circles/sines through zero, 0.2-1 of ``v_max_counts``), some holds, whole counts.

    The trajectory starts ``burn_in_s`` before the recording: a model run over the
    whole array and cut at ``start`` gives a recording that starts mid-loop.

    Returns
    -------
    t_s : ndarray, shape (m,)
        Times (s), ``t_s[start] = 0``.
    v : ndarray, shape (m,)
        Signed input (counts).
    start : int
        Index of the recording's first sample (``n_samples`` samples from there).
    """
    dt = 1.0 / rate_hz
    n_burn = int(round(burn_in_s * rate_hz))
    m = n_burn + int(n_samples)
    v = np.empty(m)
    k, phase = 0, float(rng.uniform(0.0, 2.0 * np.pi))
    while k < m:
        if rng.uniform() < hold_fraction:  # hold where the input is
            n_hold = int(rng.uniform(0.5, 2.0) * rate_hz)
            v[k : k + n_hold] = v[k - 1] if k > 0 else 0.0
            k += n_hold
            continue
        amp = rng.uniform(0.2, 1.0) * v_max_counts
        period = rng.uniform(*period_s)
        n_loop = max(int(period * rate_hz), 4)
        ph = phase + 2.0 * np.pi * np.arange(1, n_loop + 1) / n_loop
        seg = amp * np.sin(ph)
        # continue from where the input is: blend over the first quarter loop
        if k > 0:
            w = np.clip(np.arange(1, n_loop + 1) / (0.25 * n_loop), 0.0, 1.0)
            seg = (1 - w) * v[k - 1] + w * seg
        v[k : k + n_loop] = seg[: m - k]
        k += n_loop
    t = (np.arange(m) - n_burn) * dt
    return t, np.round(v), n_burn
