"""The two-tendon GPI with coupling to the other motor (model kind ``"agpi_coupled"``).

Both motors at once (docs/models.md, "Both motors at once"): the pitch tendons pass
the yaw joint, so the yaw joint's bend changes their path length and the pitch angle
follows the yaw motor too. The path length is geometry, and the yaw joint's bend is
reached by the yaw motor only through the yaw tendons' own friction and slack: the
coupling is a hysteretic map of the other motor's input, not a straight line in it.
It is modelled as a second two-tendon GPI, on the other motor's signed input::

    theta = theta0 + Y_p[max(v, 0)] - Y_n[max(-v, 0)]
                   + s_cp C_p[max(v_o, 0)] - s_cn C_n[max(-v_o, 0)]

``Y_p``, ``Y_n``: this axis's tendons (:mod:`.two_tendon`); ``C_p``, ``C_n``: GPIs of
the other input's positive and negative side (suffix ``_cp`` / ``_cn``), in the same
gauge (``a2`` held at 0: their offset is ``theta0``; ``lam`` held); ``s_cp``, ``s_cn``
(``sign_cp``, ``sign_cn``, +1 or -1, held) the direction in which each side of the
other motor moves this axis, set from the data before the fit (GPI slopes are >= 0).
At ``a1 = a3 = a4 = 0`` a coupling side is silent: the model is then exactly the
two-tendon GPI (the nested start). A linear coupling ``k v_o`` is the special case of
one operator and equal envelopes; on the simulation of docs/models.md it leaves about
four times the noise (the other joint's hysteresis), so the hysteretic form is the one
fitted.

Signals: ``v`` this axis's signed input, ``v_other`` the other motor's signed input
(counts); without ``v_other`` the coupling is silent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.hysteresis.models import (
    _gpi_columns,
    _input,
    check_settings,
    checked_values,
    gpi_model,
    gpi_output,
)
from i2ris_calib.hysteresis.start import start_values
from i2ris_calib.hysteresis.two_tendon import (
    GPI_NAMES,
    SIDES,
    TwoTendonGPIModel,
    _column_ordered,
    _in_gauge,
    _put_columns,
    _sides,
    side_input,
    two_tendon_gpi_model,
)
from i2ris_calib.model import Parameter, Signals

__all__ = [
    "COUPLING_SIDES",
    "CoupledTwoTendonModel",
    "coupled_fixed",
    "coupled_starts",
    "coupled_two_tendon_model",
]

#: Coupling side -> (side of the other input, sign of its angle)
COUPLING_SIDES = {"cp": ("p", 1.0), "cn": ("n", -1.0)}
#: Held by the gauge: each coupling side's loading envelope starts at 0
COUPLING_GAUGE = ("a2_cp", "a2_cn")
#: A coupling side is silent at these values (exactly the two-tendon GPI)
SILENT = {"a1": 0.0, "a2": 0.0, "a3": 0.0, "a4": 0.0}


@dataclass(frozen=True)
class CoupledTwoTendonModel(TwoTendonGPIModel):
    """Two-tendon GPI plus a two-tendon GPI coupling to the other motor's input
    (model kind ``"agpi_coupled"``), 35 parameters (module docstring): the 17 of the
    two-tendon GPI, then for ``cp`` and ``cn`` the 8 GPI parameters and a held sign."""

    def coupling_values(self, values: np.ndarray, side: str) -> dict[str, float]:
        """The GPI parameters of one coupling side (``"cp"`` / ``"cn"``) by GPI names."""
        val = self.named(values)
        return {k: val[f"{k}_{side}"] for k in GPI_NAMES}

    def _coupling_sides(self, signals: Signals):
        """``[(coupling side, its input without repeated samples, run index or None)]``
        of the other input (empty without one); kept for a read-only input as the own
        sides are (:func:`~.two_tendon._sides`)."""
        vo = getattr(signals, "v_other", None)
        if vo is None:
            return ()
        sides = _sides(np.asarray(vo, dtype=float))
        return [(cs, *sides[side]) for cs, (side, _) in COUPLING_SIDES.items()]

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,): :meth:`own_output` plus each of
        :meth:`other_input_terms` in turn."""
        with np.errstate(invalid="ignore", over="ignore"):  # a trial start may overflow
            y = self.own_output(signals, values)
            for term in self.other_input_terms(signals, values):
                y += term
        return y

    def own_output(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """This axis's tendons' output (deg), shape (n_samples,): the output less the
        coupling; reads ``signals.v`` only."""
        return super().evaluate(signals, values)  # of its 35 values, the first 17

    def other_input_terms(self, signals: Signals, values: np.ndarray) -> list[np.ndarray]:
        """Each coupling side's term of the output (deg, shape (n_samples,)), in the
        order :meth:`evaluate` adds them; empty without the other input. They read the
        other motor's input only (the fitter computes them once for every initial-state
        level of this axis: its pre-history holds the other input)."""
        val = self.named(values)
        terms = []
        with np.errstate(invalid="ignore", over="ignore"):  # a trial start may overflow
            for cs, u, idx in self._coupling_sides(signals):
                ys = gpi_output(u, n=self.n, **self.coupling_values(values, cs))
                sign = COUPLING_SIDES[cs][1] * val[f"sign_{cs}"]
                terms.append(sign * (ys if idx is None else ys[idx]))
        return terms

    def jacobian(
        self, signals: Signals, values: np.ndarray, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """d output / d parameters, shape (n_samples, 35) (or (len(rows), 35)), exact
        (the held signs' columns are 0); column ordered (Fortran), as LM takes it."""
        v = _input(signals)
        sel = np.arange(v.size) if rows is None else np.asarray(rows)
        jac = _column_ordered(sel.size, len(self.parameters))
        self._own_columns(v, values, sel, jac)  # this axis's 17
        sides = self._coupling_sides(signals)
        if not sides:
            jac[:, 17:] = 0.0  # no other input: the coupling is silent
        val = self.named(values)
        for k, (cs, u, idx) in enumerate(sides):
            cols = _gpi_columns(u, self.n, **self.coupling_values(values, cs))
            sign = COUPLING_SIDES[cs][1] * val[f"sign_{cs}"]
            _put_columns(jac, 17 + 9 * k, sign, cols, sel if idx is None else idx[sel])
            jac[:, 25 + 9 * k] = 0.0  # the held sign
        return jac

    def guess(self, v, theta_deg, deadband=None):  # pragma: no cover - needs v_other
        """Unchanged: the start needs the other input (:func:`coupled_starts`)."""
        return self


def coupled_two_tendon_model(n: int = 30, **values: float) -> CoupledTwoTendonModel:
    """A :class:`CoupledTwoTendonModel` with the two-tendon GPI's defaults and a silent
    coupling (signs +1), overridden by ``values``."""
    check_settings("coupled_two_tendon_model", n)
    params = list(two_tendon_gpi_model(n=n).parameters)
    side_doc = {"cp": "other motor's positive side", "cn": "other motor's negative side"}
    for cs in COUPLING_SIDES:
        for p in gpi_model(n=n).parameters:
            name = f"{p.name}_{cs}"
            params.append(
                Parameter(
                    name, value=SILENT.get(p.name, p.value), lower=p.lower, upper=p.upper,
                    fixed=p.fixed or name in COUPLING_GAUGE, unit=p.unit,
                    doc=f"coupling, {side_doc[cs]}: {p.doc}"
                    + ("; held at 0 (gauge: the offset is theta0)" if p.name == "a2" else ""),
                )
            )  # fmt: skip
        params.append(
            Parameter(
                f"sign_{cs}", value=1.0, lower=-1.0, upper=1.0, fixed=True, unit="1",
                doc=f"direction in which the {side_doc[cs]} moves this axis (+1 or -1, held)",
            )
        )  # fmt: skip
    model = CoupledTwoTendonModel("agpi_coupled", tuple(params), n=n)
    return checked_values("coupled_two_tendon_model", model, values)


def coupled_fixed(config) -> tuple[str, ...]:
    """Parameters a fit holds: the two-tendon GPI's, the ``[fit] fixed_gpi`` names on
    both coupling sides, the coupling gauge and the signs."""
    from i2ris_calib.hysteresis.two_tendon import two_tendon_fixed

    own = two_tendon_fixed(config)
    return (
        *own,
        *(f"{k}_{cs}" for k in config.fixed_gpi for cs in COUPLING_SIDES),
        *COUPLING_GAUGE,
        *(f"sign_{cs}" for cs in COUPLING_SIDES),
    )


def coupled_starts(
    model: CoupledTwoTendonModel,
    signals: Signals,
    theta: np.ndarray,
    base: dict[str, float],
    n_starts: int,
    rng: np.random.Generator,
    deadband: float = 0.0,
    *,
    joint: bool = True,
) -> tuple[CoupledTwoTendonModel, list[np.ndarray]]:
    """(model with its coupling signs set, start vectors (shape (35,) each)).

    ``base``: the fitted two-tendon GPI (its 17 values). Starts: the base with the
    coupling silent (exactly the base's output: the fit is never worse than it), and
    the base with each coupling side from the GPI start recipe on the base's residual
    against that side of the other input, the residual's mean moved into ``theta0``;
    then one backfitted start (this axis's tendons restarted on the angle less the
    first coupling start). ``joint``: also ``n_starts`` joint starts
    (:func:`joint_coupling`): this axis's tendons from the angle less the coupling's
    straight-line part, both motors' slopes fitted at once, and the coupling sides
    from the residual of that. Each side's sign: the joint fit's slope's (``joint``),
    else the base residual's correlation with that side of the other input.
    """
    from i2ris_calib.hysteresis.two_tendon import two_tendon_starts

    v = np.asarray(signals.v, dtype=float)
    vo = np.asarray(signals.v_other, dtype=float)
    theta = np.asarray(theta, dtype=float)
    x_base = {k: base[k] for k in model.names[:17]}
    agpi = two_tendon_gpi_model(n=model.n)
    resid = theta - agpi.with_values(x_base)(v)
    lines = _joint_lines(v, vo, theta) if joint else None
    signs = {}
    for k, (cs, (side, sgn)) in enumerate(COUPLING_SIDES.items()):
        u, r = _side_residual(vo, side, resid)
        on = np.isfinite(r) & (u > 0)
        corr = float(np.sum(u[on] * r[on])) if on.sum() >= 5 else 0.0
        if lines is not None and lines[3 + k] != 0:
            # the joint fit's slope: both motors' parts at once, not what the base
            # left of its own tendons (the base residual correlates with the other
            # motor through this one's misfit)
            corr = float(lines[3 + k])
        signs[cs] = 1.0 if sgn * corr >= 0 else -1.0
    model = model.with_values({f"sign_{cs}": s for cs, s in signs.items()})
    silent = model.vector(x_base | {f"{k}_{cs}": x for cs in COUPLING_SIDES
                                   for k, x in SILENT.items()})  # fmt: skip
    starts = [silent, *_with_coupling(model, x_base, resid, vo, n_starts, rng, deadband)]
    # backfitting: this axis's tendons restarted on the angle less the coupling start
    # (the base fitted without coupling has absorbed part of it)
    for x in starts[1:2]:
        coupling = model.evaluate(signals, x) - agpi.evaluate(signals, x[:17])
        own = two_tendon_starts(agpi, v, theta - coupling, 1, rng, deadband)[0]
        starts.append(np.concatenate([own, x[17:]]))
    if not joint:
        return model, starts
    # joint: both motors' straight-line parts at once, this axis's tendons from the angle
    # less the other motor's, the coupling sides from the residual of that. When the
    # coupling is a large share of the angle (both motors at once, circles: the
    # base without the other input absorbs it into a wrong basin, every start above
    # from it) these start in the right basin (measured on bench_optimum
    # agpi_coupled:112, 5 Hz, n = 362: every start above ~17,500 in cost, these ~1,000);
    # seeds of their own: the draws of the starts above stay as they were
    joint_rng = rng.spawn(1)[0]
    coupling = _joint_part(v, vo, lines)
    own = two_tendon_starts(agpi, v, theta - coupling, 1, joint_rng, deadband)[0]
    x_own = dict(zip(agpi.names, map(float, own), strict=True))
    resid = theta - agpi.evaluate(signals, own)
    starts += _with_coupling(model, x_own, resid, vo, n_starts, joint_rng, deadband)
    return model, starts


def _side_residual(vo: np.ndarray, side: str, resid: np.ndarray):
    """(that side of the other input, ``resid`` less its median where that side is at
    rest (when >= 5 samples are), NaN where not finite)."""
    u = side_input(vo, side)
    ok = np.isfinite(resid)
    rest = ok & (u == 0)
    r = resid - np.nanmedian(resid[rest]) if rest.sum() >= 5 else resid
    return u, r


def _with_coupling(
    model: CoupledTwoTendonModel,
    x_base: dict[str, float],
    resid: np.ndarray,
    vo: np.ndarray,
    n_starts: int,
    rng: np.random.Generator,
    deadband: float,
) -> list[np.ndarray]:
    """``n_starts`` start vectors: this axis's tendons at ``x_base`` (17 values), each
    coupling side from the GPI start recipe on the residual ``resid`` (of ``x_base``)
    against that side of the other input, in the model's signs; the residual's mean
    moved into ``theta0``."""
    gpi = gpi_model(n=model.n)
    signs = {cs: model.value_dict()[f"sign_{cs}"] for cs in COUPLING_SIDES}
    per_side = {}
    for cs, (side, sgn) in COUPLING_SIDES.items():
        u, r = _side_residual(vo, side, resid)
        on = np.isfinite(r) & (u > 0)
        th = np.where(on, sgn * signs[cs] * r, np.nan)
        if on.sum() >= 5 and np.ptp(u[on]) > 0:
            per_side[cs] = start_values(gpi, u, th, n_starts, rng, deadband)
        else:
            per_side[cs] = [np.array([SILENT.get(k, gpi.value_dict()[k]) for k in GPI_NAMES])]
            per_side[cs] *= n_starts
    starts = []
    for i in range(n_starts):
        vals = dict(x_base)
        for cs, (_, sgn) in COUPLING_SIDES.items():
            x, shift = _in_gauge(model, cs, per_side[cs][i])
            vals["theta0"] -= sgn * signs[cs] * shift
            vals |= {f"{k}_{cs}": float(t) for k, t in zip(GPI_NAMES, x, strict=True)}
        starts.append(model.vector(vals))
    return starts


def _joint_lines(v: np.ndarray, vo: np.ndarray, theta: np.ndarray) -> np.ndarray | None:
    """Coefficients (5,) of the angle's least-squares fit by an offset and a slope on
    each side of both inputs at once (columns: 1, this input's ``p``, ``n`` sides, the
    other input's ``p``, ``n`` sides; :func:`side_input`), or None (too few finite
    angles)."""
    X = _joint_columns(v, vo)
    ok = np.isfinite(theta)
    if ok.sum() < 2 * X.shape[1]:
        return None
    return np.linalg.lstsq(X[ok], theta[ok], rcond=None)[0]


def _joint_columns(v: np.ndarray, vo: np.ndarray) -> np.ndarray:
    cols = [np.ones(np.size(v))] + [side_input(x, s) for x in (v, vo) for s in SIDES]
    return np.column_stack(cols)


def _joint_part(v: np.ndarray, vo: np.ndarray, lines: np.ndarray | None) -> np.ndarray:
    """The other input's terms (deg, shape (n,)) of the joint fit ``lines`` (zero for None)."""
    if lines is None:
        return np.zeros(np.size(v))
    return _joint_columns(v, vo)[:, 3:] @ lines[3:]


def joint_coupling(v: np.ndarray, vo: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The coupling's straight-line part (deg, shape (n,)): the angle's least-squares
    fit by an offset and a slope on each side of both inputs at once, its terms in the
    other input (zero when too few angles are finite)."""
    return _joint_part(v, vo, _joint_lines(v, vo, theta))


assert set(SIDES) == {s for s, _ in COUPLING_SIDES.values()}
