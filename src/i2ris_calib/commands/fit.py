"""``i2ris-calib fit``: synced CSV(s) -> per-direction GPI/EGPI fits -> fit.json, predictions.csv.

The files' formats (schema ``i2ris-calib.fit/1``, docs/fit.md) are built and read in
:mod:`i2ris_calib.io.fit`; this module picks the datasets, fits, writes and prints.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from i2ris_calib.data.dataset import Dataset
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.decision import decide_fits
from i2ris_calib.fitting.fit import fit_model
from i2ris_calib.fitting.limits import dataset_limits
from i2ris_calib.fitting.pipeline import fit_dataset, pick_after_fit
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.hysteresis.registry import BUILT_KINDS, fit_order, kind_info, table_order
from i2ris_calib.io.atomic import write_json
from i2ris_calib.io.fit import (
    fit_document,
    model_file_origin,
    predictions_frame,
    read_model_file,
)
from i2ris_calib.io.outputs import claim_output_dir, output_dir, output_lock
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.synced import datasets_for_fit, load_datasets, recording_summary  # noqa: F401 (re-exported)

#: The files ``fit`` writes in its output folder.
OUTPUTS = ("fit.json", "predictions.csv")


def fit_saved(model, data: Dataset, fit_config):
    """Refit a saved (diagnosed) model to one dataset, starting from its saved values."""
    return fit_model(
        model,
        data.signals,
        data.theta_deg,
        holdout_mask=data.holdout,
        max_nfev=fit_config.max_nfev,
    )


def fit_every_kind(
    datasets: Sequence[Dataset], kinds: Sequence[str], fit_config, progress=None, saved=None
):
    """Fit every model kind to every dataset: list of (dataset, {kind: FitResult}).

    ``saved`` is an optional model from ``final_model.json`` (diagnose), fitted as kind
    ``"diagnosed"`` when that kind is listed.
    """
    out = []
    for d in datasets:
        if np.ptp(d.v) == 0:
            raise CalibError(
                f"{d.source} [{d.name}]: the input is constant; nothing to fit (check --axis)"
            )
        results = {}
        for kind in fit_order(kinds):
            if progress is not None:
                progress(f"{d.name}: {kind}")
            try:
                if kind == DIAGNOSED:
                    results[kind] = fit_saved(saved, d, fit_config)
                else:
                    results[kind] = fit_dataset(kind, d, fit_config, results)
            except CalibError as exc:
                raise CalibError(f"{d.source} [{d.name}] {kind}: {exc}") from None
        out.append((d, {k: results[k] for k in kinds}))
    return out


def source_labels(sources: Sequence[str]) -> dict[str, str]:
    """The shortest trailing part of each file path that tells it from the others
    (``A/synced.csv`` and ``B/synced.csv``; ``synced.csv`` alone), by source."""
    parts = {s: Path(s).resolve().parts for s in dict.fromkeys(sources)}
    labels = {}
    for src, mine in parts.items():
        others = [p for s, p in parts.items() if p != mine]
        k = 1
        while k < len(mine) and any(p[-k:] == mine[-k:] for p in others):
            k += 1
        labels[src] = "/".join(mine[-k:])
    return labels


def results_tables(fitted, kinds: Sequence[str], axis: str) -> list:
    """:func:`results_table` of every dataset, or one per input file when the datasets
    come from several (titled with the part of its path that tells it from the others,
    :func:`source_labels`): same-named datasets of different files are never side by
    side, and a table never gets wider than one file's directions."""
    labels = source_labels([d.source for d, _ in fitted])
    if len(set(labels.values())) < 2:
        return [results_table(fitted, kinds, axis)]
    groups: dict[str, list] = {}
    for d, results in fitted:
        groups.setdefault(labels[d.source], []).append((d, results))
    return [results_table(group, kinds, axis, source=src) for src, group in groups.items()]


def results_table(fitted, kinds: Sequence[str], axis: str, source: str | None = None):
    """A rich Table shaped like the paper's Tables 1-2: one row per model (fitted
    cycles and held-out cycles), RMSE / NRMSE / max |error| (the paper's MAE) per dataset,
    titled with the models fitted. A
    ``*`` marks each cell group whose fit did not converge (per model and dataset).
    ``source``: the one input file of these datasets, in the title (the columns are
    then labelled by direction: one dataset per direction in a file)."""

    def label(d: Dataset) -> str:
        return f"{d.axis}{d.direction}" if source else d.name

    absd = [label(d) for d, _ in fitted if d.abs_fitted]
    names = [kind_info(k).label for k in fit_order(kinds)]
    models = " and ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else names)
    table = Table(
        title=f"{models}, {axis} motor: RMSE and max |error| in deg, NRMSE in %"
        + (f"\n{source}" if source else ""),
        caption="; ".join(
            [f"{', '.join(absd)}: fitted on |counts| -> |deg|"] * bool(absd)
            + ["* = not converged"]
            * any(not r.converged for _, res in fitted for r in res.values())
        )
        or None,
    )
    table.add_column("model", no_wrap=True)
    for d, _ in fitted:
        for m in ("RMSE", "NRMSE", "max |error|"):
            table.add_column(f"{label(d)}\n{m}", justify="right", no_wrap=True)
    for kind in table_order(kinds):
        for label, attr in (("fit", "metrics"), ("hold", "holdout_metrics")):
            row = [f"{kind_info(kind).label} {label}"]
            for _, results in fitted:
                mt = getattr(results[kind], attr)
                star = "" if results[kind].converged else "*"
                row += [
                    f"{mt.rmse_deg:.2f}{star}",
                    f"{mt.nrmse_pct:.2f}{star}",
                    f"{mt.max_abs_err_deg:.2f}{star}",
                ]
            table.add_row(*[r.replace("nan", "-") for r in row])
    return table


def fit_files(
    paths: Sequence[str | Path],
    axis: str,
    model: str,
    out: str | Path,
    config,
    model_file: str | Path | None = None,
) -> dict[str, Any]:
    """Command body of ``i2ris-calib fit``: read, split, fit, write, print the table.

    ``model_file`` is a ``final_model.json`` written by ``diagnose``: that model is
    refitted too, as model ``"diagnosed"`` in fit.json. Returns the fit.json document.
    """
    if model not in (*BUILT_KINDS, "all"):
        raise CalibError(f"--model must be {', '.join(BUILT_KINDS)} or all, got '{model}'")
    if not paths:
        raise CalibError("give at least one synced CSV to fit")
    saved = read_model_file(model_file) if model_file is not None else None
    if model_file is not None:
        _check_model_axis(model_file, axis)
    inputs = [*paths, *([model_file] if model_file is not None else [])]
    out = claim_output_dir(out, "fit", inputs, OUTPUTS)
    with output_lock(out, command="fit"):  # one fit at a time into ``out``, until written
        return _fit_into(paths, axis, model, out, config, saved, inputs)


def _fit_into(paths, axis: str, model: str, out: Path, config, saved, inputs: list) -> dict:
    """The body of :func:`fit_files` once ``out`` is claimed and locked."""
    fit_config = config.fit
    datasets, choice = datasets_for_fit(paths, axis, fit_config, model, config.columns)
    kinds = (*choice.kinds, *([DIAGNOSED] if saved is not None else []))
    # plain text: a message's "[fit] n_starts" or a file label "[a.csv]" is not markup
    console = Console(stderr=True, markup=False, highlight=False, soft_wrap=True)
    with Progress(console=console, transient=True, disable=not console.is_terminal) as bar:
        task = bar.add_task("fitting", total=len(datasets) * len(kinds))

        def step(label: str) -> None:
            bar.update(task, description=f"fitting {label}", advance=1)

        fitted = fit_every_kind(datasets, kinds, fit_config, progress=step, saved=saved)
    # the one decision per dataset (fitting/decision.py), read by every later stage
    decided = [decide_fits(d, res) for d, res in fitted]
    choice = pick_after_fit(choice, fitted, [ev for _, ev in decided])
    decisions = [dec for dec, _ in decided]
    limits = [
        dataset_limits(d, res, dec, fit_config)
        for (d, res), dec in zip(fitted, decisions, strict=True)
    ]
    doc = fit_document(fitted, axis, kinds, provenance(inputs, config), choice, decisions, limits)
    for d, dec in zip(doc["datasets"], decisions, strict=True):
        for kind, reason in dec.rejected:  # the numbers behind "not recommendable"
            d["models"][kind]["warnings"].append(f"not recommended: {reason}")
    with output_dir(out, "fit", inputs, OUTPUTS) as tmp:
        write_json(tmp / "fit.json", doc)
        predictions_frame(fitted).to_csv(tmp / "predictions.csv", index=False, float_format="%.10g")
    for table in results_tables(fitted, kinds, axis):
        Console().print(table)
    labels = source_labels([d["source"] for d in doc["datasets"]])
    several = len(set(labels.values())) > 1
    console.print(choice.line)
    for dec, lim in zip(decisions, limits, strict=True):
        console.print(dec.line)
        console.print(f"{dec.dataset}: {lim.verdict}")
        for w in lim.anomalies:
            console.print(f"warning: {dec.dataset}: {w}")
    for d in doc["datasets"]:
        r = d["rows"]
        name = f"{d['name']} [{labels[d['source']]}]" if several else d["name"]
        console.print(
            f"{name}: {r['total']} samples drive the models; {r['in_direction']} are its own "
            f"({r['fitted']} fitted, {r['holdout']} held out, {r['angle_missing']} not measured)"
        )
        for kind, rec in d["models"].items():
            for w in rec["warnings"]:
                if not w.startswith("not converged"):
                    console.print(f"warning: {name} {kind}: {w}")
    if any(not r.converged for _, res in fitted for r in res.values()):
        console.print(
            "* not converged: see 'message' in fit.json (try more starts or --config [fit] max_nfev)"
        )
    return doc


def _check_model_axis(model_file, axis: str) -> None:
    """CalibError when the final_model.json was diagnosed on the other axis (its
    effects and values belong to that motor)."""
    origin = model_file_origin(model_file)
    was = origin.get("axis")
    if was is None or was == axis:
        return
    raise CalibError(
        f"{model_file}: its model was diagnosed on {origin.get('dataset', was)} (axis {was}); "
        f"this fit is --axis {axis}: give the final_model.json of a {axis} diagnosis "
        f"('diagnose ... --axis {axis}'), or fit --axis {was}"
    )
