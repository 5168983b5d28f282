"""The two-tendon GPI: one model of an axis over its whole signed input (ours).

An I2RIS axis is bent by an antagonistic tendon pair: a positive input tensions one
tendon, a negative input the other, and near zero both are slack. Each tendon has its
own friction and slack, so its own hysteresis, acting only on its side of zero
(docs/models.md, "The two-tendon GPI")::

    theta = theta0 + Y_p[max(v, 0)] - Y_n[max(-v, 0)]

``Y_p`` and ``Y_n`` are GPI models (Eq1-3, Eq14-15) with parameters of their own
(suffix ``_p`` / ``_n``), each written in the paper's per-direction convention
(|counts| -> |deg|: ``Y_n`` is the angle the negative tendon adds, with the sign
flipped). Both run over the whole recording in time order: while the input is on the
other side of zero a side's input rests at 0 and its operators hold, so its history is
carried across zero. ``theta0`` is the angle at zero input with both tendons relaxed.

Gauge: a common offset ``c`` of one side's envelopes (``a2 + c``, ``a4 + c``) moves every
operator by ``c`` (after the first excursion: only the clamped initial state differs),
i.e. the output by ``sum p c``: the same as moving ``theta0``. So ``a2_p`` and
``a2_n`` are held at 0 (each tendon's loading envelope starts at zero input) and
``theta0`` carries the offset; ``lam_p``, ``lam_n`` are held as GPI's ``lam`` (exactly
redundant with the envelope scale).

Units: input v in encoder counts, output in deg, as GPI (docs/models.md).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from i2ris_calib.hysteresis.kernel import gather_rows
from i2ris_calib.hysteresis.models import (
    ParametricModel,
    _find_runs,
    _gpi_columns,
    _input,
    check_settings,
    checked_values,
    gpi_model,
    gpi_output,
    guessed_model,
)
from i2ris_calib.hysteresis.start import start_values
from i2ris_calib.model import Parameter, Signals

__all__ = [
    "SIDES",
    "TwoTendonGPIModel",
    "side_input",
    "two_tendon_fixed",
    "two_tendon_gpi_model",
    "two_tendon_starts",
]

#: The GPI parameters of one tendon, in model order (each side's names end in ``_p`` / ``_n``)
GPI_NAMES = ("a1", "a2", "a3", "a4", "lam", "sigma", "r1", "rn")
#: Side suffix -> sign of its input and of its angle (``theta = theta0 + Y_p - Y_n``)
SIDES = {"p": 1.0, "n": -1.0}
#: Held by the gauge (module docstring): each tendon's loading envelope starts at 0
GAUGE = ("a2_p", "a2_n")


def side_input(v: np.ndarray, side: str) -> np.ndarray:
    """The input of one tendon, shape (n,): ``max(v, 0)`` (``"p"``), ``max(-v, 0)`` (``"n"``)."""
    return np.maximum(SIDES[side] * np.asarray(v, dtype=float), 0.0)


def _sides(v: np.ndarray):
    """``{side: (input without repeated samples, run index of every sample or None)}``.

    A side's input rests at 0 while the axis is on the other side of zero (about half
    of a recording through zero); a GPI is rate independent, so it is evaluated once per
    run of equal inputs. Kept for the last four read-only inputs (the fitter's copies of
    this axis's and the other motor's input, with and without a pre-history)."""
    frozen = not v.flags.writeable and v.base is None
    if frozen:
        for key, out in _SIDES_CACHE:
            if key() is v:
                return out
    out = {}
    for side in SIDES:
        u = np.ascontiguousarray(side_input(v, side))
        runs = _find_runs(u)
        out[side] = (u, None) if runs is None else runs
    if frozen:
        _SIDES_CACHE.insert(0, (weakref.ref(v), out))
        del _SIDES_CACHE[4:]
    return out


_SIDES_CACHE: list = []


def _side_of(val: dict[str, float], side: str) -> dict[str, float]:
    """The GPI parameters of one side (suffix ``side``) of named values, by GPI names."""
    return {k: val[f"{k}_{side}"] for k in GPI_NAMES}


def _column_ordered(n_rows: int, n_cols: int) -> np.ndarray:
    """A zeroed (n_rows, n_cols) float array in column (Fortran) order: each column
    contiguous, filled by :func:`_put_columns` without strided writes. Zeroed, not
    uninitialised: a side the input never reaches (one-signed input, a coupling side
    the other motor never drives) writes no columns, and its parameters move nothing
    (an uninitialised buffer left garbage there and made fits differ run to run)."""
    return np.zeros((n_cols, n_rows)).T


def _put_columns(jac: np.ndarray, first: int, sign: float, cols: np.ndarray, at) -> None:
    """``jac[:, first:first + q] = sign * cols[at]`` (``cols`` shape (m, q)), compiled
    (:func:`~.kernel.gather_rows`; the same values as the fancy-indexed assignment)."""
    gather_rows(
        jac, int(first), float(sign), np.ascontiguousarray(cols, dtype=float),
        np.ascontiguousarray(at, dtype=np.int64),
    )  # fmt: skip


@dataclass(frozen=True)
class TwoTendonGPIModel(ParametricModel):
    """Two-tendon GPI over the signed input (model kind ``"agpi"``), 17 parameters.

    ``theta = theta0 + Y_p[max(v, 0)] - Y_n[max(-v, 0)]`` (module docstring), ``Y_s`` a
    GPI with linear envelopes ``gamma_l = a1_s u + a2_s``, ``gamma_r = a3_s u + a4_s``
    and density ``p(r) = lam_s exp(-sigma_s r)`` on ``n + 1`` thresholds
    (``r_0 = 0``, ``r_1..r_n`` uniform on ``[r1_s, rn_s]``; Eq1-3, Eq14-15).
    """

    n: int = 30

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,)."""
        v = _input(signals)
        val = self.named(values)  # once (a diagnosis evaluates a model ~50,000 times)
        y = np.full(v.size, float(val["theta0"]))
        for side, (u, idx) in _sides(v).items():
            ys = gpi_output(u, n=self.n, **_side_of(val, side))  # Eq1-3 per tendon
            y += SIDES[side] * (ys if idx is None else ys[idx])
        return y

    def jacobian(
        self, signals: Signals, values: np.ndarray, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """d output / d parameters (deg per unit), shape (n_samples, 17) (or (len(rows),
        17)), exact (each side's GPI Jacobian, :func:`~.kernel.play_jacobian`); column
        ordered (Fortran), as LM takes it."""
        v = _input(signals)
        sel = np.arange(v.size) if rows is None else np.asarray(rows)
        jac = _column_ordered(sel.size, len(self.parameters))
        self._own_columns(v, values, sel, jac)
        return jac

    def _own_columns(self, v, values, sel, jac) -> None:
        """Write the 17 columns of this axis's tendons (theta0, then each side's GPI
        columns) at the samples ``sel`` into ``jac`` (in place)."""
        jac[:, 0] = 1.0  # theta0
        val = self.named(values)
        for k, (side, (u, idx)) in enumerate(_sides(v).items()):
            cols = _gpi_columns(u, self.n, **_side_of(val, side))
            _put_columns(jac, 1 + 8 * k, SIDES[side], cols, sel if idx is None else idx[sel])

    def guess(
        self, v: np.ndarray, theta_deg: np.ndarray, deadband: float | None = None
    ) -> TwoTendonGPIModel:
        """A new model whose values are the data-driven start for (v, theta)
        (:func:`two_tendon_starts`); fixed parameters keep their values."""
        return guessed_model(self, two_tendon_starts, v, theta_deg, deadband)


def two_tendon_gpi_model(n: int = 30, **values: float) -> TwoTendonGPIModel:
    """A two-tendon GPI (:class:`TwoTendonGPIModel`) with default values (each side
    GPI's defaults moved into the gauge ``a2 = 0``), overridden by ``values``."""
    check_settings("two_tendon_gpi_model", n)
    params = [
        Parameter(
            "theta0", value=0.0, lower=-500.0, upper=500.0, unit="deg",
            doc="angle at zero input with both tendons relaxed",
        ),
    ]  # fmt: skip
    tendon = {"p": "positive-input tendon", "n": "negative-input tendon (|counts| -> |deg|)"}
    for side in SIDES:
        for p in gpi_model(n=n, a2=0.0, a4=-1.0).parameters:
            params.append(
                Parameter(
                    f"{p.name}_{side}", value=p.value, lower=p.lower, upper=p.upper,
                    fixed=p.fixed or f"{p.name}_{side}" in GAUGE, unit=p.unit,
                    doc=f"{tendon[side]}: {p.doc}"
                    + ("; held at 0 (gauge: the offset is theta0)" if p.name == "a2" else ""),
                )
            )  # fmt: skip
    model = TwoTendonGPIModel("agpi", tuple(params), n=n)
    return checked_values("two_tendon_gpi_model", model, values)


def two_tendon_fixed(config) -> tuple[str, ...]:
    """Parameters a fit holds: the ``[fit] fixed_gpi`` names on both sides, and the gauge."""
    return (*(f"{k}_{s}" for k in config.fixed_gpi for s in SIDES), *GAUGE)


def _rest_angle(v: np.ndarray, theta: np.ndarray) -> float:
    """Start of ``theta0``: the median angle of the samples nearest zero input (within
    the zero band, else the 2 % of smallest |v|), deg."""
    from i2ris_calib.hysteresis.bands import input_bands

    ok = np.isfinite(theta)
    if not ok.any():
        return 0.0
    a = np.abs(v[ok])
    near = a <= input_bands(v).zero_band
    if near.sum() < 5:
        near = a <= np.quantile(a, 0.02)
    return float(np.median(theta[ok][near]))


def _in_gauge(model: TwoTendonGPIModel, side: str, x: np.ndarray) -> tuple[np.ndarray, float]:
    """A side's GPI start ``x`` (GPI order, shape (8,)) with the model's fixed ``lam`` and
    ``a2`` (same output), and the change of that side's output it costs (deg; moved
    into theta0). Scale: ``(a1..a4, r1, rn) / c``, ``lam c``, ``sigma c`` give the same
    output (docs/models.md, choice 4); shift: ``a2 + d``, ``a4 + d`` add ``sum p d``."""
    a1, a2, a3, a4, lam, sigma, r1, rn = (float(t) for t in x)
    par = {p.name: p for p in model.parameters}
    if par[f"lam_{side}"].fixed and lam > 0:
        c = par[f"lam_{side}"].value / lam
        a1, a2, a3, a4, r1, rn = (t / c for t in (a1, a2, a3, a4, r1, rn))
        lam, sigma = lam * c, sigma * c
    shift = 0.0
    if par[f"a2_{side}"].fixed:
        d = par[f"a2_{side}"].value - a2
        r = np.concatenate(([0.0], np.linspace(r1, rn, model.n)))
        shift = float(np.sum(lam * np.exp(-sigma * r))) * d
        a2, a4 = a2 + d, a4 + d
    return np.array([a1, a2, a3, a4, lam, sigma, r1, rn]), shift


def two_tendon_starts(
    model: TwoTendonGPIModel,
    v: np.ndarray,
    theta: np.ndarray,
    n_starts: int,
    rng: np.random.Generator,
    deadband: float = 0.0,
) -> list[np.ndarray]:
    """``n_starts`` data-driven start vectors (shape (17,) each) for a two-tendon GPI.

    ``theta0``: the median angle near zero input. Each side: the GPI start recipe
    (:func:`.start.start_values`: envelope lines from the branches, shape from the
    angle range) on that side's own samples, input ``max(+-v, 0)`` and angle
    ``+-(theta - theta0)`` (NaN elsewhere); then put in the gauge (fixed ``lam``,
    ``a2``), the offset moved into ``theta0``. A side without samples keeps the
    model's values.
    """
    v = np.asarray(v, dtype=float)
    theta = np.asarray(theta, dtype=float)
    theta0 = _rest_angle(v, theta)
    gpi = gpi_model(n=model.n)
    base = model.value_dict()
    per_side = {}
    for side, sign in SIDES.items():
        u = side_input(v, side)
        own = (sign * v > 0) & np.isfinite(theta)
        th = np.where(own, sign * (theta - theta0), np.nan)
        if own.sum() >= 5 and np.ptp(u[own]) > 0:
            per_side[side] = start_values(gpi, u, th, n_starts, rng, deadband)
        else:
            per_side[side] = [np.array([base[f"{k}_{side}"] for k in GPI_NAMES])] * n_starts
    starts = []
    for i in range(n_starts):
        vals = {"theta0": theta0}
        for side, sign in SIDES.items():
            x, shift = _in_gauge(model, side, per_side[side][i])
            vals["theta0"] -= sign * shift
            vals |= {f"{k}_{side}": float(t) for k, t in zip(GPI_NAMES, x, strict=True)}
        starts.append(model.vector(vals))
    return starts
