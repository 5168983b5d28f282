"""Which fitted model the report recommends per dataset, why, and where the data end.

The model is the one ``fit`` decided (fit.json ``datasets[].decision``, the rule of
:mod:`i2ris_calib.fitting.decision`); this module adds the words around it. For an
older fit.json without a decision: the default model ``fit`` picked after fitting on a
signed input (fit.json ``model_choice``), else among the models that converged, the
lowest held-out RMSE wins; the continuous EGPI_C is preferred over the paper's EGPI when
its held-out RMSE is within :data:`CONTINUOUS_MARGIN` of it. Parameters the data do not identify are
named. The supported range is that of the dataset's own measured samples: outside
it the model extrapolates.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.fitting.decision import CONTINUOUS_MARGIN, Decision
from i2ris_calib.hysteresis.kinds import CONTINUOUS_EGPI, PAPER_BASELINE
from i2ris_calib.hysteresis.registry import ALL_KINDS, kind_info
from i2ris_calib.report.tables import (
    FIT_MODELS,
    PROFILED_PARAMS,
    at_bound,
    fmt_sig,
    not_converged,
    unidentified,
)

CONTINUOUS_KIND = CONTINUOUS_EGPI
"""The continuous EGPI: recommended over a kind whose output steps at its flag point
(registry ``output_steps``: EGPI) within :data:`CONTINUOUS_MARGIN`."""

LABELS = dict(FIT_MODELS)


@dataclass(frozen=True)
class Recommendation:
    """The recommended model of one dataset.

    Attributes
    ----------
    dataset : str
        Dataset name (``yaw+`` ...).
    model : str or None
        fit.json model key (``egpi`` ...); None when no model converged with a held-out error.
    rmse_deg : float
        Its held-out RMSE (deg); NaN when none.
    why : str
        One or two sentences: the comparison, output jumps, identifiability.
    support : str
        The input (and angle) range the dataset's measured samples cover.
    """

    dataset: str
    model: str | None
    rmse_deg: float
    why: str
    support: str

    @property
    def label(self) -> str:
        """Display name of the model (``EGPI_C``), or an em dash."""
        return LABELS.get(self.model, "—") if self.model else "—"


def _holdout(d: Mapping[str, Any], key: str) -> float:
    rec = d.get("models", {}).get(key) or {}
    try:
        v = float((rec.get("holdout_metrics") or {}).get("rmse_deg"))
    except (TypeError, ValueError):
        return float("nan")
    return v if math.isfinite(v) else float("nan")


def supported_range(d: Mapping[str, Any], pred: pd.DataFrame | None) -> str:
    """Input and angle range of the dataset's own measured samples (predictions.csv),
    else fit.json's ``input_range_counts``; ``"unknown"`` without either."""
    if pred is not None and not pred.empty:
        own = pred[(pred["split"].astype(str) != "other")]
        theta = own["theta_deg"].to_numpy(dtype=float)
        ok = np.isfinite(theta)
        if ok.any():
            v = own["v"].to_numpy(dtype=float)[ok]
            return (
                f"input {fmt_sig(v.min(), 4)}–{fmt_sig(v.max(), 4)} counts, angle "
                f"{fmt_sig(theta[ok].min(), 3)}–{fmt_sig(theta[ok].max(), 3)} deg"
            )
    rng = d.get("input_range_counts")
    if isinstance(rng, list) and len(rng) == 2:
        return f"input {fmt_sig(rng[0], 4)}–{fmt_sig(rng[1], 4)} counts"
    return "unknown"


def recommend(
    d: Mapping[str, Any], pred: pd.DataFrame | None = None, choice: Mapping | None = None
) -> Recommendation:
    """The :class:`Recommendation` for one fit.json dataset record (rule: module doc).

    ``choice``: the fit's ``model_choice``; when its default model was picked after
    fitting (``picked_after_fit``: the signed input) and converged here, that model is
    recommended with the figures that picked it (one rule: fitting/pipeline.py
    ``pick_after_fit``)."""
    name = str(d.get("name", "dataset"))
    support = supported_range(d, pred)
    cands = _holdout_candidates(d)
    decided = d.get("decision")
    if isinstance(decided, Mapping):  # the one decision, made by fit (fitting/decision.py)
        dec = Decision.from_dict(name, decided)
        if dec.model is None or dec.model not in d.get("models", {}):
            return Recommendation(
                name, None, float("nan"), f"no model recommended: {dec.why}.", support
            )
        best, why = dec.model, [dec.why]
        cands.setdefault(best, _holdout(d, best))
    elif not cands:
        return Recommendation(
            name, None, float("nan"), "no converged model with a held-out error", support
        )
    else:  # an older fit.json without a decision
        best, why = _preferred_model(cands, choice)
    why.append(_identification_note(d, best))
    info = kind_info(best) if best in ALL_KINDS else None
    if info is not None and info.coupled:
        why.append(
            "it also reads the other motor's input: predict and compensate both axes together"
        )
    if PAPER_BASELINE in cands and best != PAPER_BASELINE:
        ratio = cands[PAPER_BASELINE] / cands[best] if cands[best] > 0 else float("nan")
        if math.isfinite(ratio) and ratio > 1:
            why.append(f"GPI is {fmt_sig(ratio, 2, pad=True)}x worse")
    return Recommendation(name, best, cands[best], "; ".join(why) + ".", support)


def _holdout_candidates(d: Mapping[str, Any]) -> dict[str, float]:
    """Held-out RMSE (deg) of every converged model of :data:`FIT_MODELS` that has a
    finite one, in that order."""
    cands = {
        k: _holdout(d, k)
        for k, _ in FIT_MODELS
        if k in d.get("models", {}) and not not_converged(d, k)
    }
    return {k: v for k, v in cands.items() if math.isfinite(v)}


def _preferred_model(cands: Mapping[str, float], choice: Mapping | None) -> tuple[str, list[str]]:
    """The recommended model among ``cands`` (held-out RMSE, deg) and the reasons so far.

    The fit's default model when it was picked after fitting and converged; else the
    lowest held-out RMSE, EGPI_C preferred over EGPI within :data:`CONTINUOUS_MARGIN`.
    """
    best = min(cands, key=cands.__getitem__)
    ranked = sorted(cands.items(), key=lambda kv: kv[1])
    why = [f"lowest held-out RMSE ({fmt_sig(cands[best], 2, pad=True)} deg"]
    if len(ranked) > 1:
        k2, v2 = ranked[1]
        why[0] += f"; next {LABELS[k2]} {fmt_sig(v2, 2, pad=True)} deg)"
    else:
        why[0] += ")"
    fitted_pick = isinstance(choice, Mapping) and choice.get("picked_after_fit")
    picked = choice.get("main") if fitted_pick else None
    if picked in cands:
        best = picked
        text = str(choice.get("why", ""))
        at = text.find("picked after fitting")
        why = [text[at:] if at >= 0 else f"the fit's default model ({best})"]
    elif kind_info(best).output_steps and CONTINUOUS_KIND in cands:
        c, e, label = cands[CONTINUOUS_KIND], cands[best], LABELS[best]
        if c <= e * (1 + CONTINUOUS_MARGIN):
            best = CONTINUOUS_KIND
            why = [
                f"held-out RMSE {fmt_sig(c, 2, pad=True)} deg, within "
                f"{100 * CONTINUOUS_MARGIN:.0f} % of {label}'s {fmt_sig(e, 2, pad=True)} deg, "
                f"and no output step at the flag point ({label} jumps there)"
            ]
        else:
            why.append(f"{label}'s output steps at the flag point (mind it when inverting)")
    elif kind_info(best).output_steps:
        why.append("its output steps at the flag point (mind it when inverting)")
    return best, why


def _identification_note(d: Mapping[str, Any], best: str) -> str:
    """Which fitted parameters of model ``best`` the data do not identify, or that all
    are identified (profiled ones named)."""
    bad = unidentified(d, best)
    bound = at_bound(d, best)
    free = d["models"][best].get("free") or d["models"][best].get("params") or []
    n_free = len([n for n in free if n not in PROFILED_PARAMS])
    edge = f"{', '.join(bound)} at a bound (the lowest cost found has it there)" if bound else ""
    if bad:
        return (
            f"{len(bad)} parameter(s) not identified by these data ({', '.join(bad)}): "
            "trust the predictions, not those values" + (f"; {edge}" if edge else "")
        )
    if bound:
        return f"the other fitted parameters identified; {edge}"
    profiled = [n for n in free if n in PROFILED_PARAMS]
    return f"all {n_free} fitted parameters identified" + (
        f" ({', '.join(profiled)} profiled)" if profiled else ""
    )
