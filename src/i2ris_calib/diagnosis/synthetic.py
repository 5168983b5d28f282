"""Synthetic diagnosis cases with known truth: EGPI data with one hidden effect.

Used by the tests (``tests/diagnosis``) and the benchmark
(``benchmarks/bench_diagnosis.py``). The input is a loading trajectory like the
I2RIS recordings (ramps out and back with pauses) but with strokes at several
speeds, so rate effects are identifiable; the other axis moves slowly and
independently so coupling is identifiable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.data.dataset import direction_of_samples, input_bands, make_dataset
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.hysteresis.effects import CATALOGUE, build_model, model_values
from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import paper_like_params
from i2ris_calib.model import Model, Signals

#: Hidden-effect parameter sets per effect, weakest first: each effect's ``strengths``
#: (:class:`~i2ris_calib.hysteresis.effects.Effect`), by name in catalogue order.
STRENGTHS: dict[str, tuple[dict[str, float], ...]] = {
    name: tuple(dict(p) for p in e.strengths) for name, e in CATALOGUE.items()
}


def excitation(
    rng: np.random.Generator,
    n_cycles: int = 8,
    v_max_counts: float = 6000.0,
    rate_hz: float = 30.0,
    speeds_counts_s: tuple[float, ...] = (300.0, 800.0, 2000.0),
    pause_s: float = 1.5,
) -> tuple[np.ndarray, np.ndarray]:
    """Ramps out and back with pauses; amplitude and speed vary per cycle.

    The first and last cycles go to full scale; other amplitudes are
    U(0.4, 1) of full scale; each cycle's speed is drawn from
    ``speeds_counts_s``. Values are whole counts.

    Returns
    -------
    t_s : ndarray, shape (n,)
        Times (s) at ``rate_hz``.
    v : ndarray, shape (n,)
        Input (counts), >= 0.
    """
    kt, kv = [0.0], [0.0]
    for i in range(n_cycles):
        a = 1.0 if i in (0, n_cycles - 1) else rng.uniform(0.4, 1.0)
        speed = float(speeds_counts_s[i % len(speeds_counts_s)] * rng.uniform(0.9, 1.1))
        top = a * v_max_counts
        for dt, val in ((pause_s, 0.0), (top / speed, top), (pause_s, top), (top / speed, 0.0)):
            kt.append(kt[-1] + dt)
            kv.append(val)
    kt.append(kt[-1] + pause_s)
    kv.append(0.0)
    t = np.arange(0.0, kt[-1], 1.0 / rate_hz)
    return t, np.round(np.interp(t, kt, kv))


@dataclass(frozen=True)
class Case:
    """One synthetic data set.

    Attributes
    ----------
    signals : Signals
        ``v``, ``t_s``, and the other axis's ``v_other`` and measured
        ``theta_other_deg``.
    theta_deg : ndarray, shape (n,)
        Measured angle of this axis (truth + white noise).
    truth : Model
        Truth model (EGPI, wrapped by the hidden effect if any).
    effect : str or None
        Hidden effect name (None for a clean case).
    noise_deg : float
        Noise standard deviation (deg).
    """

    signals: Signals
    theta_deg: np.ndarray
    truth: Model
    effect: str | None
    noise_deg: float


def make_case(
    seed: int,
    effect: str | None = None,
    params: dict[str, float] | None = None,
    noise_deg: float = 0.2,
    n_cycles: int = 8,
) -> Case:
    """A case: EGPI (``paper_like_params("yaw+")``) + optional hidden effect + noise.

    Parameters
    ----------
    seed : int
        Seeds the trajectory and the noise.
    effect : str, optional
        Catalogue name of the hidden effect.
    params : dict, optional
        Its parameter values (default: the middle entry of :data:`STRENGTHS`).
    noise_deg : float
        White measurement noise (deg) on both axes.
    """
    rng = np.random.default_rng(seed)
    t, v = excitation(rng, n_cycles=n_cycles)
    v_other = np.round(3000.0 + 2800.0 * np.sin(2 * np.pi * t / 37.0 + rng.uniform(0, 2 * np.pi)))
    other = i2ris_egpi_model(**paper_like_params("pitch+"))
    th_other = other(v_other) + rng.normal(0.0, noise_deg, t.size)
    base = i2ris_egpi_model(**paper_like_params("yaw+"))
    effects = {} if effect is None else {effect: params or STRENGTHS[effect][1]}
    truth = build_model(base, effects)
    sig = Signals(v=v, t_s=t, v_other=v_other, theta_other_deg=th_other)
    theta = truth.evaluate(sig, model_values(truth)) + rng.normal(0.0, noise_deg, t.size)
    return Case(sig, theta, truth, effect, noise_deg)


def make_two_direction_case(
    seed: int,
    effect: str | None = None,
    params: dict[str, float] | None = None,
    noise_deg: float = 0.2,
    n_cycles: int = 12,
) -> Case:
    """A signed recording: loading cycles alternately positive and negative.

    The trajectory of :func:`make_case` with every second cycle mirrored to negative
    input. Each direction has its own truth (``paper_like_params("yaw+")`` and
    ``("yaw-")``, the same hidden effect), driven by the input that direction sees
    over the whole history (``max(enc, 0)``, ``max(-enc, 0)``); the measured angle is
    the ``"+"`` truth on the ``"+"`` samples and minus the ``"-"`` truth on the ``"-"``
    samples (attribution of :func:`i2ris_calib.data.dataset.direction_of_samples`),
    plus noise. ``signals.v`` is the signed input; ``truth`` is the ``"-"`` truth (in
    the ``"-"`` dataset's convention, the angle is ``-theta``).
    """
    rng = np.random.default_rng(seed)
    t, v = excitation(rng, n_cycles=n_cycles)
    moving = v > 0
    starts = moving & ~np.concatenate([[False], moving[:-1]])
    sign = np.where(np.cumsum(starts) % 2 == 1, 1.0, -1.0)
    enc = sign * v
    v_other = np.round(3000.0 + 2800.0 * np.sin(2 * np.pi * t / 37.0 + rng.uniform(0, 2 * np.pi)))
    other = i2ris_egpi_model(**paper_like_params("pitch+"))
    th_other = other(v_other) + rng.normal(0.0, noise_deg, t.size)
    effects = {} if effect is None else {effect: params or STRENGTHS[effect][1]}
    side = direction_of_samples(enc, input_bands(enc).zero_band)
    theta = np.zeros(t.size)
    truths = {}
    for d, s in (("+", 1.0), ("-", -1.0)):
        truth = build_model(i2ris_egpi_model(**paper_like_params(f"yaw{d}")), effects)
        sig_d = Signals(
            v=np.maximum(s * enc, 0.0), t_s=t, v_other=v_other, theta_other_deg=th_other
        )
        theta += np.where(side == s, s * truth.evaluate(sig_d, model_values(truth)), 0.0)
        truths[d] = truth
    theta += rng.normal(0.0, noise_deg, t.size)
    sig = Signals(v=enc, t_s=t, v_other=v_other, theta_other_deg=th_other)
    return Case(sig, theta, truths["-"], effect, noise_deg)


def case_dataset(case: Case, fit_config=None, axis: str = "yaw", direction: str = "+"):
    """The case as the ``direction`` :class:`~i2ris_calib.data.Dataset` that
    ``diagnose`` and ``fit`` would build from its synced CSV (bands derived from the
    input unless ``fit_config`` sets them, its held-out cycles from
    ``fit_config.holdout_fraction``).

    The input of :func:`make_case` never goes negative, so every sample is in its
    ``"+"`` dataset; :func:`make_two_direction_case` has both.
    """

    cfg = fit_config or FitConfig()
    s = case.signals
    return make_dataset(
        axis,
        direction,
        s.t_s,
        s.v,
        case.theta_deg,
        enc_other=s.v_other,
        theta_other_deg=s.theta_other_deg,
        bands=input_bands(s.v, cfg.zero_band_counts, cfg.deadband_counts),
        holdout_fraction=cfg.holdout_fraction,
        source=f"synthetic case ({case.effect or 'clean'})",
    )
