"""Fit GPI and EGPI to one motion-direction dataset: build, start, split, fit.

Also splits a session's samples into motion-direction datasets by the sign of the
axis input (``direction_blocks``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.cycles import cycle_index, default_deadband, holdout_mask
from i2ris_calib.fitting.fit import FitResult, fit_model
from i2ris_calib.fitting.initial import start_values
from i2ris_calib.hysteresis.model import Signals
from i2ris_calib.hysteresis.models import ParametricModel, gpi_model, i2ris_egpi_model

MODEL_KINDS = ("gpi", "egpi")


def deadband_for(v: np.ndarray, config: FitConfig) -> float:
    """The ``v'`` dead band (counts): configured, or 1 % of the input range."""
    return default_deadband(v) if config.deadband_counts < 0 else float(config.deadband_counts)


def build_model(kind: str, v: np.ndarray, config: FitConfig = FitConfig()) -> ParametricModel:
    """An unfitted ``"gpi"`` or ``"egpi"`` (I2RIS) model set up from ``config``."""
    if kind == "gpi":
        return gpi_model(n=config.n_operators).with_fixed(fixed=config.fixed_gpi)
    if kind == "egpi":
        m = i2ris_egpi_model(n=config.n_operators, deadband_counts=deadband_for(v, config))
        free = ("v_f",) if config.fit_flag_point and "v_f" not in config.fixed_egpi else ()
        return m.with_fixed(fixed=config.fixed_egpi, free=free)
    raise CalibError(f"unknown model '{kind}'; use gpi, egpi or all")


def model_from_params(
    kind: str, params: dict[str, float], n_operators: int = 30, deadband_counts: float = 2.0
) -> ParametricModel:
    """A fitted model rebuilt from a fit.json record's ``params`` (and its
    ``n_operators`` / ``deadband_counts``)."""
    if kind == "gpi":
        return gpi_model(n=n_operators, **params)
    if kind == "egpi":
        return i2ris_egpi_model(n=n_operators, deadband_counts=deadband_counts, **params)
    raise CalibError(f"unknown model '{kind}'; use gpi or egpi")


def split_masks(v: np.ndarray, config: FitConfig = FitConfig()) -> tuple[np.ndarray, np.ndarray]:
    """(cycle index (n,), held-out mask (n,)) for ``v`` (see fitting.cycles)."""
    cyc = cycle_index(v, deadband_for(v, config))
    return cyc, holdout_mask(cyc, config.holdout_fraction, v)


def fit_kind(
    kind: str,
    signals: Signals | np.ndarray,
    theta_deg: np.ndarray,
    config: FitConfig = FitConfig(),
    holdout: np.ndarray | None = None,
    gpi_fit: FitResult | None = None,
) -> FitResult:
    """Fit one model kind with data-driven, seeded multi-start (docs/fit.md).

    EGPI nests GPI (``a5 = a3, a6 = a4, kappa = 1``, any ``v_f``: same output), so
    one EGPI start is the GPI fit mapped into EGPI (:func:`nested_gpi_start`); the
    EGPI result is never worse than it (fit_model keeps the best start as a floor).

    Parameters
    ----------
    kind : {"gpi", "egpi"}
    signals : Signals or ndarray, shape (n,)
        Input (counts, |counts| for a negative dataset).
    theta_deg : ndarray, shape (n,)
        Measured angle (deg), NaN allowed.
    holdout : ndarray of bool, shape (n,), optional
        Held-out samples; default from :func:`split_masks`.
    gpi_fit : FitResult, optional
        GPI fit on the same samples and holdout (``kind="egpi"`` only); fitted here
        when not given.
    """
    s = signals if isinstance(signals, Signals) else Signals(v=np.asarray(signals, dtype=float))
    v = np.asarray(s.v, dtype=float)
    theta = np.asarray(theta_deg, dtype=float)
    if holdout is None:
        holdout = split_masks(v, config)[1]
    model = build_model(kind, v, config)
    n_starts = config.n_starts if kind == "egpi" else config.n_starts_gpi
    rng = np.random.default_rng(config.seed)
    fit_sel = np.isfinite(theta) & ~holdout
    theta_fit = np.where(fit_sel, theta, np.nan)
    starts = (
        start_values(model, v, theta_fit, n_starts, rng, deadband_for(v, config))
        if fit_sel.sum() > 2
        else None
    )
    if starts is not None and kind == "egpi":
        if gpi_fit is None:
            gpi_fit = fit_kind("gpi", s, theta, config, holdout)
        starts.append(nested_gpi_start(model, gpi_fit.params, starts[0]))
    if starts is not None:
        starts = [_keep_fixed(model, x) for x in starts]
    return fit_model(
        model,
        s,
        theta,
        holdout_mask=holdout,
        starts=starts,
        method=config.method,
        max_nfev=config.max_nfev,
        loss=config.loss,
        f_scale_deg=config.f_scale_deg,
    )


def nested_gpi_start(
    model: ParametricModel, gpi_params: dict[str, float], start: np.ndarray
) -> np.ndarray:
    """EGPI start vector, shape (p,), giving exactly the GPI output of ``gpi_params``:
    ``a5 = a3``, ``a6 = a4``, ``kappa = 1`` (both families equal, so the flag point
    ``v_f``, taken from ``start``, does not matter)."""
    vals = dict(zip(model.names, np.asarray(start, dtype=float), strict=True))
    vals |= {k: float(x) for k, x in gpi_params.items() if k in vals}
    vals |= {"a5": vals["a3"], "a6": vals["a4"], "kappa": 1.0}
    return model.vector(vals)


def _keep_fixed(model: ParametricModel, x: np.ndarray) -> np.ndarray:
    """Fixed parameters keep the model's values, except lam (scale gauge) and v_f."""
    x = np.array(x, dtype=float)
    for i, p in enumerate(model.parameters):
        if p.fixed and p.name not in ("lam", "v_f"):
            x[i] = p.value
    return x


def fit_all(
    signals: Signals | np.ndarray,
    theta_deg: np.ndarray,
    config: FitConfig = FitConfig(),
    kinds: tuple[str, ...] = MODEL_KINDS,
) -> dict[str, FitResult]:
    """``{kind: FitResult}`` on one dataset with one shared held-out split."""
    v = np.asarray(signals.v if isinstance(signals, Signals) else signals, dtype=float)
    holdout = split_masks(v, config)[1]
    out: dict[str, FitResult] = {}
    for k in kinds:
        out[k] = fit_kind(k, signals, theta_deg, config, holdout, gpi_fit=out.get("gpi"))
    return out


@dataclass(frozen=True)
class DirectionBlock:
    """Samples of one motion direction of one axis.

    Attributes
    ----------
    direction : str
        ``"+"`` or ``"-"``.
    index : ndarray of int
        Row indices (into the session arrays) of the samples, in time order; the
        blocks of one direction are concatenated.
    """

    direction: str
    index: np.ndarray


def direction_blocks(
    enc_counts: np.ndarray, config: FitConfig = FitConfig()
) -> list[DirectionBlock]:
    """Split samples into motion-direction datasets by the sign of the axis input.

    A sample with ``enc > zero_band_counts`` belongs to "+", one with
    ``enc < -zero_band_counts`` to "-", the rest (the axis at rest, e.g. while the
    other motor moves) to none. The excursions of one sign are concatenated in time
    order (the operators are rate independent; the input is continuous across the
    cut because both ends lie near the zero band). Datasets with fewer than
    ``min_block_samples`` samples are dropped.
    """
    e = np.asarray(enc_counts, dtype=float)
    out = []
    for label, keep in (("+", e > config.zero_band_counts), ("-", e < -config.zero_band_counts)):
        if keep.sum() >= config.min_block_samples:
            out.append(DirectionBlock(label, np.flatnonzero(keep)))
    return out
