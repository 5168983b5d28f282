"""Which fitted model to trust: the one decision per dataset, made once after fitting.

``fit`` writes it to fit.json (``datasets[].decision``); the report, ``run``,
``compensate`` (CLI and ``Compensator.from_fit``), ``diagnose`` and the API read it.
An entry point that cannot use the decided model (no inverse, a coupled model given
one axis) takes the next model of its ranking and says which and why
(:meth:`Decision.model_for`).

The rule (:func:`decide`):

1. A fitted model is a candidate when it converged with a finite held-out RMSE.
2. It is **usable** unless (each reason stated, :meth:`Evidence.problems`):

   - none of its fitted parameters is identified (every standard error missing or
     larger than the value);
   - a parameter sits on a bound that is not a sign constraint (a bound other than 0:
     a search box) and moving it off the bound moves the output
     (:data:`BOUND_STEP` of its range changes the output by more than
     :data:`BOUND_MOVES_NOISE` noise sd): the fit leans on the box, not on the data;
   - its held-out error from rest, or after a conditioning sweep of the input range,
     is more than :data:`START_RATIO_MAX` x its error from the fitted start state (a
     start a user cannot reproduce);
   - its output jumps: its largest sample-to-sample change exceeds the data's own by
     more than :data:`JUMP_NOISE_SD` noise sd.

3. Among the usable models the lowest held-out RMSE wins; a model with fewer free
   parameters within :data:`SIMPLER_WITHIN` of it is preferred, and a continuous
   model (EGPI_C) is preferred over one whose output steps at its flag point (EGPI)
   within :data:`CONTINUOUS_MARGIN`.
4. When no model is usable, none is recommended; :attr:`Decision.fallback` names the
   least bad one (lowest held-out RMSE) for entry points that need a model, and every
   reader says it is not recommended.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from i2ris_calib.hysteresis.kinds import CONTINUOUS_EGPI
from i2ris_calib.hysteresis.registry import ALL_KINDS, kind_info

SCHEMA = "i2ris-calib.decision/1"
"""Schema id of the ``decision`` record in fit.json."""

SIMPLER_WITHIN = 0.05
"""A model with fewer free parameters is preferred within this share of the lowest
held-out RMSE."""
CONTINUOUS_MARGIN = 0.10
"""A continuous model (EGPI_C) is preferred over one whose output steps at its flag
point (EGPI) when its held-out RMSE is at most this much higher (relative)."""
CONTINUOUS_KIND = CONTINUOUS_EGPI
"""The continuous EGPI."""
JUMP_NOISE_SD = 3.0
"""A model's output "jumps" when its largest sample-to-sample change exceeds the data's
own largest change by more than this many noise sd (:func:`output_jump`)."""
START_RATIO_MAX = 2.0
"""Largest ratio of the held-out error from rest (or after a conditioning sweep) to
that from the fitted start state of a recommendable model."""
BOUND_STEP = 0.01
"""Step off a bound, as a share of the parameter's range, to see whether it moves the
output."""
BOUND_MOVES_NOISE = 0.1
"""A bound "moves the output" when :data:`BOUND_STEP` off it changes the output by
more than this many noise sd (RMS over the measured samples)."""
PROFILED = ("v_f",)
"""Parameters fitted by a profile search (no standard error by construction)."""


def output_jump(pred: np.ndarray, theta: np.ndarray) -> float:
    """How far a model's largest output change between consecutive measured samples
    exceeds the measured angle's own largest change there (deg; negative: within it).

    ``pred``, ``theta``: shape (n,), the model output and the measured angle (NaN where
    not measured); only pairs of consecutive samples both measured count."""
    y, th = np.asarray(pred, dtype=float), np.asarray(theta, dtype=float)
    both = np.isfinite(th[1:]) & np.isfinite(th[:-1]) & np.isfinite(y[1:]) & np.isfinite(y[:-1])
    if not both.any():
        return float("nan")
    return float(np.abs(np.diff(y))[both].max() - np.abs(np.diff(th))[both].max())


@dataclass(frozen=True)
class Evidence:
    """What the decision reads of one fitted model on one dataset.

    Attributes
    ----------
    kind : str
        Model kind (registry name, or ``diagnosed``).
    holdout_rmse_deg : float
        Held-out RMSE (deg); NaN when none.
    n_holdout : int
        Held-out samples.
    converged : bool
        The fit converged.
    n_free : int
        Free parameters.
    unidentified : tuple of str
        Free parameters (not profiled) whose standard error is missing or exceeds the
        value (not those on a bound).
    n_identified : int or None
        Free parameters (not profiled) with a standard error within the value; None
        when the fit carries no standard errors.
    bound_moving : tuple of str
        Parameters on a bound other than 0 that move the output (:data:`BOUND_STEP`).
    jump_sd : float
        :func:`output_jump` in noise sd (NaN: not measured).
    jump_deg : float
        :func:`output_jump` in deg.
    start_ratio : float
        Held-out RMSE from rest or after a conditioning sweep (the lower) over that
        from the fitted start state (1 when the fit starts at rest; NaN: unknown).
    rest_rmse_deg : float
        That held-out RMSE from rest / after the sweep (deg).
    """

    kind: str
    holdout_rmse_deg: float
    n_holdout: int = 0
    converged: bool = True
    n_free: int = 0
    unidentified: tuple[str, ...] = ()
    n_identified: int | None = None
    bound_moving: tuple[str, ...] = ()
    jump_sd: float = float("nan")
    jump_deg: float = float("nan")
    start_ratio: float = float("nan")
    rest_rmse_deg: float = float("nan")

    def problems(self) -> list[str]:
        """Why this model is not recommendable (empty: usable), in plain words."""
        out = []
        if not self.converged:
            out.append("not converged")
        if not math.isfinite(self.holdout_rmse_deg):
            out.append("no held-out error")
        if self.n_identified == 0 and self.unidentified:
            out.append(
                f"no fitted parameter identified by these data ({', '.join(self.unidentified)})"
            )
        if self.bound_moving:
            out.append(
                f"{', '.join(self.bound_moving)} on a bound of the search box that moves the "
                "output (the fit leans on the box, not on the data)"
            )
        if math.isfinite(self.start_ratio) and self.start_ratio > START_RATIO_MAX:
            out.append(
                f"its held-out error from rest or after a conditioning sweep is "
                f"{self.start_ratio:.1f}x that from the fitted start state "
                f"({self.rest_rmse_deg:.3g} vs {self.holdout_rmse_deg:.3g} deg): a start "
                "a user cannot reproduce"
            )
        if math.isfinite(self.jump_sd) and self.jump_sd > JUMP_NOISE_SD:
            out.append(
                f"its output jumps by {self.jump_deg:.3g} deg more than the data's largest "
                f"sample-to-sample change ({self.jump_sd:.1f} noise sd)"
            )
        return out


@dataclass(frozen=True)
class Decision:
    """The recommended model of one dataset, with its reasons.

    Attributes
    ----------
    dataset : str
        Dataset name (``yaw+``, ``pitch±`` ...).
    model : str or None
        The recommended kind; None when no model is usable (:attr:`fallback`).
    why : str
        The figures that decided, in one or two sentences.
    ranking : tuple of str
        Every candidate, best first: the usable ones by the rule, then the others by
        held-out RMSE.
    held_out_rmse_deg : tuple of (str, float)
        Each candidate's held-out RMSE (deg).
    rejected : tuple of (str, str)
        The candidates that are not recommendable and why.
    fallback : str or None
        With no usable model: the one with the lowest held-out RMSE (for entry points
        that need a model; they say it is not recommended).
    """

    dataset: str
    model: str | None
    why: str
    ranking: tuple[str, ...] = ()
    held_out_rmse_deg: tuple[tuple[str, float], ...] = ()
    rejected: tuple[tuple[str, str], ...] = ()
    fallback: str | None = None

    @property
    def line(self) -> str:
        """One line for the terminal, e.g. ``yaw+: recommended egpi (...)``."""
        if self.model is None:
            return f"{self.dataset}: no model recommended ({self.why})"
        return f"{self.dataset}: recommended {self.model} ({self.why})"

    def model_for(self, refusal: Callable[[str], str | None]) -> tuple[str | None, str]:
        """(kind, note) for an entry point that cannot use every kind: ``refusal(kind)``
        says why it cannot use ``kind`` (None: it can), e.g. ``"bouc_wen has no
        inverse"``. The decided model when it can; else the first of :attr:`ranking` it
        can, the note saying which model it uses instead of the recommended one and why
        (empty when the recommended model is used). (None, note) when it can use none."""
        wanted = self.model if self.model is not None else self.fallback
        held = dict(self.held_out_rmse_deg)
        rejected = dict(self.rejected)
        if wanted is None:
            return None, f"{self.dataset}: no fitted model ({self.why})"
        reason = refusal(wanted)
        if reason is None:
            if self.model is None:
                return wanted, (
                    f"{self.dataset}: no model is recommended ({self.why}); using {wanted}, "
                    "the lowest held-out RMSE"
                )
            return wanted, ""
        for kind in self.ranking:
            if kind != wanted and refusal(kind) is None:
                note = (
                    f"{self.dataset}: using {kind} (held-out {held.get(kind, math.nan):.3g} deg) "
                    f"instead of the recommended {wanted}: {reason}"
                )
                if kind in rejected:
                    note += f"; {kind} is not recommendable itself ({rejected[kind]})"
                return kind, note
        return (
            None,
            f"{self.dataset}: the recommended {wanted} cannot be used ({reason}) and no other model can",
        )

    def as_dict(self) -> dict[str, Any]:
        """The fit.json ``decision`` record."""
        return {
            "schema": SCHEMA,
            "model": self.model,
            "why": self.why,
            "line": self.line,
            "ranking": list(self.ranking),
            "held_out_rmse_deg": dict(self.held_out_rmse_deg),
            "rejected": dict(self.rejected),
            "fallback": self.fallback,
        }

    @classmethod
    def from_dict(cls, dataset: str, doc: Mapping[str, Any]) -> Decision:
        """The decision of a fit.json ``decision`` record (``dataset``: its name)."""
        held = doc.get("held_out_rmse_deg") or {}
        return cls(
            dataset=dataset,
            model=doc.get("model"),
            why=str(doc.get("why", "")),
            ranking=tuple(str(k) for k in doc.get("ranking") or ()),
            held_out_rmse_deg=tuple((str(k), float(v)) for k, v in held.items()),
            rejected=tuple((str(k), str(v)) for k, v in (doc.get("rejected") or {}).items()),
            fallback=doc.get("fallback"),
        )


def _info(kind: str):
    return kind_info(kind) if kind in ALL_KINDS else None


def decide(dataset: str, evidence: Sequence[Evidence]) -> Decision:
    """The :class:`Decision` of one dataset from its models' :class:`Evidence` (the
    rule: module doc)."""
    cands = [e for e in evidence if math.isfinite(e.holdout_rmse_deg)]
    held = tuple((e.kind, float(e.holdout_rmse_deg)) for e in cands)
    if not cands:
        return Decision(dataset, None, "no model with a held-out error")
    problems = {e.kind: e.problems() for e in cands}
    usable = [e for e in cands if not problems[e.kind]]
    others = sorted((e for e in cands if problems[e.kind]), key=lambda e: e.holdout_rmse_deg)
    rejected = tuple((e.kind, "; ".join(problems[e.kind])) for e in others)
    if not usable:
        fallback = others[0].kind
        why = "; ".join(f"{k}: {r}" for k, r in rejected)
        return Decision(dataset, None, f"no model is usable: {why}",
                        tuple(e.kind for e in others), held, rejected, fallback)  # fmt: skip
    pick, text = _preferred(usable)
    order = [pick.kind] + [e.kind for e in sorted(usable, key=lambda e: e.holdout_rmse_deg)
                           if e.kind != pick.kind]  # fmt: skip
    if rejected:
        rmse = dict(held)
        text += "; not recommendable: " + "; ".join(
            f"{k} {rmse[k]:.3g} deg ({r})" for k, r in rejected
        )
    ranking = tuple(order) + tuple(e.kind for e in others)
    return Decision(dataset, pick.kind, text, ranking, held, rejected)


def _preferred(usable: Sequence[Evidence]) -> tuple[Evidence, str]:
    """The recommended one of the usable models and the figures that decided."""
    rmse = {e.kind: e.holdout_rmse_deg for e in usable}
    best = min(usable, key=lambda e: (e.holdout_rmse_deg, e.n_free))
    simpler = [e for e in usable if e.n_free < best.n_free
               and e.holdout_rmse_deg <= (1 + SIMPLER_WITHIN) * best.holdout_rmse_deg]  # fmt: skip
    pick = min(simpler, key=lambda e: (e.n_free, e.holdout_rmse_deg)) if simpler else best
    note = ""
    if pick is not best:
        note = f" (fewer parameters, within {100 * SIMPLER_WITHIN:.0f} % of {best.kind} {best.holdout_rmse_deg:.3g} deg)"
    info = _info(pick.kind)
    cont = next((e for e in usable if e.kind == CONTINUOUS_KIND), None)
    if info is not None and info.output_steps and cont is not None:
        if cont.holdout_rmse_deg <= (1 + CONTINUOUS_MARGIN) * pick.holdout_rmse_deg:
            note = (
                f" (within {100 * CONTINUOUS_MARGIN:.0f} % of {pick.kind} "
                f"{pick.holdout_rmse_deg:.3g} deg, and no output step at the flag point)"
            )
            pick = cont
    others = sorted((k for k in rmse if k != pick.kind), key=rmse.__getitem__)
    text = f"{pick.kind}: held-out {pick.holdout_rmse_deg:.3g} deg"
    if others:
        text += " vs " + ", ".join(f"{k} {rmse[k]:.3g} deg" for k in others)
    return pick, text + note


# -- evidence of fitted models ----------------------------------------------------------


def noise_sd(results: Mapping[str, Any]) -> float:
    """The dataset's noise sd bound (deg): the lowest fitted RMSE of its models."""
    vals = [float(r.metrics.rmse_deg) for r in results.values()]
    vals = [x for x in vals if math.isfinite(x) and x > 0]
    return min(vals) if vals else float("nan")


def evidence_of(kind: str, result, data, noise: float) -> Evidence:
    """The :class:`Evidence` of one fitted model (``result``: a FitResult) on its
    dataset (``data``: a :class:`~i2ris_calib.data.dataset.Dataset`); ``noise``: the
    dataset's noise sd (:func:`noise_sd`)."""
    hm = result.holdout_metrics
    pred = np.asarray(result.predict(data.signals), dtype=float)
    jump = output_jump(pred, data.theta_measured_deg)
    unident, n_ident = _identification(result)
    ratio, rest = _start_ratio(result, data)
    return Evidence(
        kind=kind,
        holdout_rmse_deg=float(hm.rmse_deg),
        n_holdout=int(getattr(hm, "n_samples", 0) or 0),
        converged=bool(result.converged),
        n_free=len(result.free),
        unidentified=unident,
        n_identified=n_ident,
        bound_moving=_bounds_moving(result, data, pred, noise),
        jump_sd=jump / noise if math.isfinite(jump) and noise > 0 else float("nan"),
        jump_deg=jump,
        start_ratio=ratio,
        rest_rmse_deg=rest,
    )


def _identification(result) -> tuple[tuple[str, ...], int | None]:
    """(the free parameters not identified, how many are), profiled and bound ones
    left out; (``()``, None) for a result without standard errors."""
    stderr = getattr(result, "stderr", None)
    if not isinstance(stderr, Mapping):
        return (), None
    reasons = getattr(result, "stderr_reasons", {}) or {}
    bad, good = [], 0
    for n in result.free:
        if n in PROFILED or str(reasons.get(n, "")).startswith("at its bound"):
            continue
        se, val = float(stderr.get(n, float("nan"))), float(result.params.get(n, float("nan")))
        if math.isfinite(se) and math.isfinite(val) and se <= abs(val):
            good += 1
        else:
            bad.append(n)
    return tuple(bad), good


def _bounds_moving(result, data, pred: np.ndarray, noise: float) -> tuple[str, ...]:
    """Free parameters on a bound other than 0 that move the output (module doc)."""
    model = getattr(result, "model", None)
    if model is None or not hasattr(model, "parameters") or not (noise > 0):
        return ()
    reasons = getattr(result, "stderr_reasons", {}) or {}
    measured = np.isfinite(np.asarray(data.theta_deg, dtype=float))
    out = []
    x = np.array([p.value for p in model.parameters], dtype=float)
    for i, p in enumerate(model.parameters):
        if p.name not in result.free or not str(reasons.get(p.name, "")).startswith("at its bound"):
            continue
        lo, hi = float(p.lower), float(p.upper)
        at_lo = abs(p.value - lo) <= abs(p.value - hi)
        edge = lo if at_lo else hi
        if edge == 0.0:
            continue  # a sign constraint, not a search box
        span = hi - lo if math.isfinite(hi - lo) else max(abs(p.value), 1.0)
        xs = x.copy()
        xs[i] += (1.0 if at_lo else -1.0) * BOUND_STEP * span
        moved = replace(result, model=model.with_values(xs)).predict(data.signals)
        d = (np.asarray(moved, dtype=float) - pred)[measured]
        if d.size and float(np.sqrt(np.nanmean(d**2))) > BOUND_MOVES_NOISE * noise:
            out.append(p.name)
    return tuple(out)


def _start_ratio(result, data) -> tuple[float, float]:
    """(held-out RMSE from rest or after a conditioning sweep, the lower, over that from
    the fitted start; that RMSE in deg); (1, held-out RMSE) for a fit from rest."""
    held = float(result.holdout_metrics.rmse_deg)
    if getattr(result, "initial_state", None) is None:
        return 1.0, held
    from i2ris_calib.fitting.prehistory import prehistory_signals

    mask = np.asarray(data.holdout, bool) & np.isfinite(np.asarray(data.theta_deg, dtype=float))
    if not mask.any() or not (held > 0):
        return float("nan"), float("nan")
    theta = np.asarray(data.theta_deg, dtype=float)
    x = np.array([p.value for p in result.model.parameters], dtype=float)
    own = np.asarray(data.v, dtype=float)[np.asarray(data.in_direction, bool)]
    lo, hi = (float(own.min()), float(own.max())) if own.size else (0.0, 0.0)

    def rmse(y: np.ndarray) -> float:
        return float(np.sqrt(np.mean((np.asarray(y, dtype=float)[mask] - theta[mask]) ** 2)))

    errs = [rmse(result.predict(data.signals, initial_state=False))]
    for turn, frm in ((hi, lo), (lo, hi)):  # relaxed at one end, swept to the other
        sig, n_pre = prehistory_signals(data.signals, frm, v_turn=turn)
        errs.append(rmse(result.model.evaluate(sig, x)[n_pre:]))
    best = min(e for e in errs if math.isfinite(e)) if any(map(math.isfinite, errs)) else math.nan
    return best / held, best


def decide_fits(data, results: Mapping[str, Any]) -> tuple[Decision, dict[str, Evidence]]:
    """(the :class:`Decision` of one dataset's fits ``results`` (kind -> FitResult),
    the evidence it read)."""
    noise = noise_sd(results)
    ev = {k: evidence_of(k, r, data, noise) for k, r in results.items()}
    return decide(str(getattr(data, "name", "dataset")), list(ev.values())), ev


def pooled(evidence: Sequence[Evidence]) -> Evidence:
    """One kind's evidence over several datasets: held-out RMSE pooled by samples, the
    worst of the rest."""
    w = np.array([max(e.n_holdout, 1) for e in evidence], dtype=float)
    r = np.array([e.holdout_rmse_deg for e in evidence], dtype=float)
    rmse = float(np.sqrt(np.sum(w * r**2) / np.sum(w))) if w.sum() else float("nan")

    def worst(vals: list[float]) -> float:
        vals = [v for v in vals if math.isfinite(v)]
        return max(vals) if vals else float("nan")

    idents = [e.n_identified for e in evidence if e.n_identified is not None]
    return Evidence(
        kind=evidence[0].kind,
        holdout_rmse_deg=rmse,
        n_holdout=int(w.sum()),
        converged=all(e.converged for e in evidence),
        n_free=max(e.n_free for e in evidence),
        unidentified=tuple(dict.fromkeys(n for e in evidence for n in e.unidentified)),
        n_identified=min(idents) if idents else None,
        bound_moving=tuple(dict.fromkeys(n for e in evidence for n in e.bound_moving)),
        jump_sd=worst([e.jump_sd for e in evidence]),
        jump_deg=worst([e.jump_deg for e in evidence]),
        start_ratio=worst([e.start_ratio for e in evidence]),
        rest_rmse_deg=worst([e.rest_rmse_deg for e in evidence]),
    )
