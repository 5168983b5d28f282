"""``i2ris-calib fit``: synced CSV(s) -> per-direction GPI/EGPI fits -> fit.json, predictions.csv.

The files' formats (schema ``i2ris-calib.fit/1``, docs/fit.md) are built and read in
:mod:`i2ris_calib.io.fit`; this module picks the datasets, fits, writes and prints.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from dataclasses import fields as dataclass_fields
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from i2ris_calib.data.dataset import Dataset
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.decision import decide_fits
from i2ris_calib.fitting.fit import fit_model, lower_optimum
from i2ris_calib.fitting.limits import dataset_limits
from i2ris_calib.fitting.pipeline import dataset_cost, fit_dataset, pick_after_fit
from i2ris_calib.fitting.prehistory import InitialState
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.hysteresis.registry import BUILT_KINDS, fit_order, kind_info, table_order
from i2ris_calib.io.atomic import write_json
from i2ris_calib.io.config_io import dataclass_to_dict
from i2ris_calib.io.fit import (
    fit_document,
    model_file_origin,
    predictions_frame,
    read_fit_json,
    read_model_file,
    replacement_record,
)
from i2ris_calib.io.fit_records import load_model
from i2ris_calib.io.outputs import claim_output_dir, output_dir, output_lock
from i2ris_calib.io.provenance import file_sha256, provenance
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
    datasets: Sequence[Dataset],
    kinds: Sequence[str],
    fit_config,
    progress=None,
    saved=None,
    given: dict[tuple[str, str], tuple[dict, ...]] | None = None,
):
    """Fit every model kind to every dataset: list of (dataset, {kind: FitResult}).

    ``saved`` is an optional model from ``final_model.json`` (diagnose), fitted as kind
    ``"diagnosed"`` when that kind is listed. ``given``: (dataset name, kind) -> further
    starts of that fit (a lower cost a later stage found, :func:`rerun_fit`).
    """
    given = given or {}
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
                    results[kind] = fit_dataset(
                        kind, d, fit_config, results, given=given.get((d.name, kind), ())
                    )
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


def _fit_into(
    paths, axis: str, model: str, out: Path, config, saved, inputs: list, rerun=None
) -> dict:
    """The body of :func:`fit_files` once ``out`` is claimed and locked; ``rerun``: the
    :class:`_Rerun` of :func:`rerun_fit` (further starts, the fit.json it replaces;
    nothing printed)."""
    fit_config = config.fit
    datasets, choice = datasets_for_fit(paths, axis, fit_config, model, config.columns)
    kinds = (*choice.kinds, *([DIAGNOSED] if saved is not None else []))
    if rerun is not None:
        rerun.check_kinds(kinds)
    # plain text: a message's "[fit] n_starts" or a file label "[a.csv]" is not markup
    console = Console(stderr=True, markup=False, highlight=False, soft_wrap=True)
    shown = console.is_terminal and rerun is None
    with Progress(console=console, transient=True, disable=not shown) as bar:
        task = bar.add_task("fitting", total=len(datasets) * len(kinds))

        def step(label: str) -> None:
            bar.update(task, description=f"fitting {label}", advance=1)

        given = rerun.given if rerun is not None else None
        fitted = fit_every_kind(datasets, kinds, fit_config, step, saved, given)
    replaced = rerun.replaced(fitted, fit_config) if rerun is not None else None
    if rerun is not None and not rerun.changes:
        return rerun.previous  # the rerun kept no lower cost: fit.json is left alone
    # the one decision per dataset (fitting/decision.py), read by every later stage
    decided = [decide_fits(d, res) for d, res in fitted]
    choice = pick_after_fit(choice, fitted, [ev for _, ev in decided])
    decisions = [dec for dec, _ in decided]
    limits = [
        dataset_limits(d, res, dec, fit_config)
        for (d, res), dec in zip(fitted, decisions, strict=True)
    ]
    doc = fit_document(fitted, axis, kinds, provenance(inputs, config), choice, decisions,
                       limits, replaced)  # fmt: skip
    for d, dec in zip(doc["datasets"], decisions, strict=True):
        for kind, reason in dec.rejected:  # the numbers behind "not recommendable"
            d["models"][kind]["warnings"].append(f"not recommended: {reason}")
    with output_dir(out, "fit", inputs, OUTPUTS) as tmp:
        write_json(tmp / "fit.json", doc)
        predictions_frame(fitted).to_csv(tmp / "predictions.csv", index=False, float_format="%.10g")
    if rerun is not None:
        return doc
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


# ---- a lower cost found by a later stage: the fit rerun from it (issue 31) ----------


@dataclass(frozen=True)
class LowerCost:
    """A lower cost of a stored fit's model that a later stage found on the same data.

    Attributes
    ----------
    dataset, kind : str
        The fit.json dataset (``pitch+``) and model kind (``egpi``).
    params : dict
        The values that reach it (the fit's parameter names, the input's unit).
    cost, stored_cost : float
        Their cost and the stored fit's, both the fit's own loss over the dataset's
        fitted samples (:func:`~i2ris_calib.fitting.pipeline.dataset_cost`).
    found_by : str
        Where it came from, e.g. ``"diagnose's refit from creep_log's values"``.
    """

    dataset: str
    kind: str
    params: dict[str, float]
    cost: float
    stored_cost: float
    found_by: str


def stored_model(doc: dict, record: dict, kind: str, path: Path):
    """(model, start state) of fit.json ``doc``'s ``kind`` in dataset ``record``: the
    stored values and the fit's :class:`~i2ris_calib.fitting.prehistory.InitialState` (None:
    the recording starts at rest)."""
    model = load_model(doc, record, kind, path)
    st = record["models"][kind].get("initial_state")
    names = {f.name for f in dataclass_fields(InitialState)}
    state = InitialState(**{k: v for k, v in st.items() if k in names}) if st else None
    return model, state


def stored_fit_record(fit_json: Path, dset: Dataset, config) -> tuple[dict, dict]:
    """(fit.json document, the record of ``dset``'s dataset in it) when ``fit_json`` was
    fitted on the same data with the same loss as ``dset`` and can be rerun (its inputs
    unchanged where it recorded them, the same ``[fit]`` and ``[columns]`` settings);
    else a one-line CalibError saying what differs (checked before any work)."""
    fit_json = Path(fit_json)
    doc = read_fit_json(fit_json)
    _invocation(doc, fit_json, config)
    record = next((d for d in doc["datasets"] if d.get("name") == dset.name), None)
    where = f"--fit {fit_json}"
    if record is None:
        have = ", ".join(str(d.get("name")) for d in doc["datasets"])
        raise CalibError(
            f"{where}: no dataset {dset.name} (it has {have}); give the fit.json of this "
            "recording's axis, fitted with the same [fit] settings"
        )
    src = Path(str(record.get("source", "")))
    if not src.is_file() or src.resolve() != Path(dset.source).resolve():
        raise CalibError(
            f"{where}: its {dset.name} was fitted on {record.get('source')}, not "
            f"{dset.source}; give the fit.json of this file"
        )
    if dict(record.get("rows") or {}) != dict(dset.rows):
        raise CalibError(
            f"{where}: its {dset.name} holds other samples ({record.get('rows')}) than "
            f"{dset.source} gives now ({dict(dset.rows)}); refit the file first"
        )
    return doc, record


def _json(x):
    return json.loads(json.dumps(dataclass_to_dict(x), default=str))


def _invocation(doc: dict, fit_json: Path, config) -> tuple[list[str], str, str | None]:
    """(input paths, ``--model``, ``--model-file`` or None) of the fit that wrote
    ``doc``, read from its provenance; CalibError when it cannot be rerun as it was
    (an input gone or changed, other ``[fit]`` or ``[columns]`` settings)."""
    prov = doc.get("provenance") or {}
    inputs = prov.get("inputs") or {}
    where = f"--fit {fit_json}"
    for name, sha in inputs.items():
        p = Path(name)
        if not p.is_file():
            raise CalibError(
                f"{where}: its input {name} is not found from this folder; run from the "
                "folder the fit ran in, or give the fit.json of the file you diagnose"
            )
        if file_sha256(p) != sha:
            raise CalibError(f"{where}: its input {name} has changed since the fit; refit it first")
    recorded = prov.get("config") or {}
    for section in ("fit", "columns"):
        if recorded.get(section) != _json(getattr(config, section)):
            raise CalibError(
                f"{where}: fitted with other [{section}] settings than this run's (another "
                "dataset or loss); give the same --config, or refit"
            )
    names = list(inputs)
    diagnosed = any(DIAGNOSED in (d.get("models") or {}) for d in doc["datasets"])
    model_file = names.pop() if diagnosed and len(names) > 1 else None
    kinds = [k for k in (doc.get("model_choice") or {}).get("kinds") or [] if k != DIAGNOSED]
    return names, (kinds[0] if len(kinds) == 1 else "all"), model_file


class _Rerun:
    """A fit rerun with further starts (:func:`rerun_fit`): the starts, the fit.json it
    replaces and, once fitted, the models whose cost fell."""

    def __init__(self, previous: dict, path: Path, lower: Sequence[LowerCost], stage: str):
        self.previous, self.path, self.stage = previous, path, stage
        self.sha256 = file_sha256(path)
        self.lower = {(c.dataset, c.kind): c for c in lower}
        self.given = {key: (c.params,) for key, c in self.lower.items()}
        self.changes: list[dict] = []

    def check_kinds(self, kinds) -> None:
        """CalibError when the rerun would fit other kinds than the stored fit."""
        was = tuple((self.previous.get("model_choice") or {}).get("kinds") or ())
        now = tuple(k for k in kinds if k != DIAGNOSED)
        if was and was != now:
            raise CalibError(
                f"{self.path}: the fit would now fit {', '.join(now)}, it fitted "
                f"{', '.join(was)}; refit it first"
            )

    def replaced(self, fitted, fit_config) -> dict[tuple[str, str], dict]:
        """(dataset, kind) -> ``replaced`` record of every model whose cost the rerun
        lowered (:func:`~i2ris_calib.fitting.fit.lower_optimum`), their certificates
        saying so (in place in ``fitted``); :attr:`changes` lists them (also a model
        the rerun left higher, which is said, never silent)."""
        out = {}
        for d, results in fitted:
            record = next(r for r in self.previous["datasets"] if r["name"] == d.name)
            for kind, res in results.items():
                if kind not in record["models"] or kind == DIAGNOSED:
                    continue
                model, state = stored_model(self.previous, record, kind, self.path)
                before = dataset_cost(model, d, fit_config, state)
                after = dataset_cost(res.model, d, fit_config, res.initial_state)
                if not (lower_optimum(before, after) or lower_optimum(after, before)):
                    continue
                found = self.lower.get((d.name, kind))
                by = found.found_by if found else f"the fit rerun from {self._sources()}"
                if lower_optimum(after, before):
                    by += "; HIGHER than the stored fit: the rerun's search ended elsewhere"
                rec = replacement_record(d.name, kind, before, after, by, self.stage,
                                         record["models"][kind]["params"], self.sha256)  # fmt: skip
                out[d.name, kind] = rec
                self.changes.append({"dataset": d.name, "kind": kind, **rec})
                if res.certificate is not None:
                    cert = replace(res.certificate, replaced=rec["text"])
                    results[kind] = replace(res, certificate=cert)
        if not any((c["dataset"], c["kind"]) in self.lower for c in self.changes):
            self.changes = []  # the lower cost was not kept: nothing is replaced
            return {}
        return out

    def _sources(self) -> str:
        return " and ".join(f"{c.dataset} {c.kind}'s lower cost" for c in self.lower.values())


def rerun_fit(fit_json: Path, lower: Sequence[LowerCost], config, stage: str) -> list[dict]:
    """Rerun the fit that wrote ``fit_json`` (its inputs and ``--model`` from its
    provenance) with each :class:`LowerCost` as one more start of its model, and write
    fit.json and predictions.csv anew (atomically, the fit's own code: decision, limits
    and model choice follow) with a ``replaced`` record on every model whose cost fell.

    Returns the changes (dataset, kind, previous_cost, cost, found_by, text, ...);
    empty when the rerun kept no lower cost, and fit.json is then left as it was.
    """
    fit_json = Path(fit_json)
    doc = read_fit_json(fit_json)
    paths, model, model_file = _invocation(doc, fit_json, config)
    saved = read_model_file(model_file) if model_file is not None else None
    inputs = [*paths, *([model_file] if model_file is not None else [])]
    out = claim_output_dir(fit_json.parent, "fit", inputs, OUTPUTS)
    with output_lock(out, command="fit"):
        if read_fit_json(fit_json) != doc:
            raise CalibError(f"{fit_json} changed while it was read; run again")
        rerun = _Rerun(doc, fit_json, lower, stage)
        _fit_into(paths, doc["axis"], model, out, config, saved, inputs, rerun)
        return rerun.changes
