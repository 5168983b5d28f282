"""Reading what compensation needs from a fit.json (docs/formats.md, fit.json): a
dataset's record and what the compensation plan reads of it
(:class:`~i2ris_calib.compensation.plan.FittedDataset`: its range, the recording's
fastest input move, its models' held-out errors, its decision), its models rebuilt.
Used by ``compensate`` and the online :class:`~i2ris_calib.io.online.Compensator`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from i2ris_calib.compensation.plan import FittedDataset
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.decision import Decision
from i2ris_calib.hysteresis.codec import model_from_fit_json
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.io.fit import read_model_file

__all__ = [
    "API_NAMES",
    "CLI_NAMES",
    "dataset_names",
    "dataset_record",
    "fitted_dataset",
    "record_decision",
    "holdout_rmse",
    "load_model",
    "virgin_identified",
]

#: How messages name the choices: the ``compensate`` command's options, or the
#: arguments of ``Compensator.from_fit`` (a Python caller has no command-line flags).
CLI_NAMES = {
    "dataset": "--dataset",
    "omit": "omit it to let compensate choose",
    "model": "--model",
    "model_file": "--model-file",
    "rate": "--max-counts-per-s",
}
API_NAMES = {
    "dataset": "dataset=",
    "omit": "omit it for the signed dataset or the first",
    "model": "model=",
    "model_file": "model_file=",
    "rate": "max_counts_per_s=",
}


def dataset_record(doc: dict, name: str, path: Path, names: dict = CLI_NAMES) -> dict:
    """The record of dataset ``name`` in fit.json ``doc`` (read from ``path``); a
    one-line CalibError naming the datasets it has when there is none (the choice
    named as ``names`` says: :data:`CLI_NAMES` or :data:`API_NAMES`)."""
    have = names
    found = [d.get("name") for d in doc.get("datasets", [])]
    for d in doc.get("datasets", []):
        if d.get("name") == name:
            return d
    raise CalibError(
        f"{path}: no dataset '{name}' (it has {', '.join(map(str, found)) or 'none'}); "
        f"choose {have['dataset']} from those ({have['omit']}) or fit that direction"
    )


def dataset_names(doc: dict) -> list[str]:
    """The dataset names of fit.json ``doc`` (``yaw+``, ``pitch±``, ...), file order."""
    return [str(d.get("name")) for d in doc.get("datasets", [])]


def load_model(
    doc: dict,
    record: dict,
    kind: str,
    path: Path,
    model_file: Path | None = None,
    names: dict = CLI_NAMES,
):
    """The fitted model ``kind`` of a fit.json dataset record, rebuilt (messages name
    the choices as ``names`` says: :data:`CLI_NAMES` or :data:`API_NAMES`)."""
    models = record.get("models", {})
    if kind not in models:
        raise CalibError(
            f"{path}: dataset '{record['name']}' has no '{kind}' model (it has "
            f"{', '.join(models) or 'none'}); choose {names['model']} from those or re-run 'fit'"
        )
    rec = models[kind]
    if kind == DIAGNOSED:
        if model_file is None:
            raise CalibError(
                f"{names['model']} diagnosed needs {names['model_file']} final_model.json (the "
                "diagnosed model's structure; fit.json holds its refitted values)"
            )

        base = read_model_file(model_file)
        names = [p.name for p in base.parameters]
        missing = [n for n in names if n not in rec["params"]]
        if missing:
            raise CalibError(
                f"{model_file}: its parameters {', '.join(missing)} are not in {path}'s "
                "diagnosed model; give the final_model.json that 'fit --model-file' used"
            )
        lacking = [n for n in rec["params"] if n not in names]
        if lacking:  # e.g. the fit's time delay: inverting without it is wrong
            raise CalibError(
                f"{model_file} does not match {path} [{record['name']}]: the fit's diagnosed "
                f"model has {', '.join(lacking)}, the model file not (another base kind or "
                "effects); give the final_model.json that 'fit --model-file' used"
            )
        return base.with_values(np.array([rec["params"][n] for n in names], dtype=float))
    try:  # the values are numbers (read_fit_json); the model may still refuse them
        return model_from_fit_json(kind, rec)
    except CalibError as exc:
        raise CalibError(
            f"{path}: dataset '{record['name']}', model '{kind}': {exc} (re-run 'fit' or "
            "restore the file)"
        ) from None


def holdout_rmse(rec: dict) -> float | None:
    """A fit.json model record's held-out RMSE (deg), else its fitted RMSE, else None."""
    for key in ("holdout_metrics", "metrics"):
        x = (rec.get(key) or {}).get("rmse_deg")
        if x is not None and np.isfinite(x):
            return float(x)
    return None


def record_decision(record: dict) -> Decision:
    """The dataset record's recommended model (fit.json ``decision``, written by ``fit``:
    :mod:`i2ris_calib.fitting.decision`). An older fit.json without one: its converged
    models ranked by held-out RMSE, the lowest first, and ``why`` says the file predates
    the decision (refit to get it)."""
    name = str(record.get("name", "dataset"))
    doc = record.get("decision")
    if isinstance(doc, dict):
        return Decision.from_dict(name, doc)
    models = record.get("models") or {}
    held = {k: holdout_rmse(rec) for k, rec in models.items() if isinstance(rec, dict)}
    held = {k: v for k, v in held.items() if v is not None}
    ok = [k for k in held if models[k].get("converged", True)]
    ranking = tuple(sorted(ok, key=held.__getitem__)) + tuple(
        sorted((k for k in held if k not in ok), key=held.__getitem__)
    )
    why = "fit.json has no decision (written by an older version; refit to get one): lowest held-out RMSE"
    best = ranking[0] if ranking else None
    return Decision(name, best, why, ranking, tuple(held.items()))


def virgin_identified(record: dict) -> bool | None:
    """Whether the fit knows the model's state at rest: True when its recording started
    at rest (no model of the dataset has an estimated ``initial_state``), False when it
    started mid-loop (an ``initial_state`` was estimated), None when fit.json does not
    say (older files)."""
    models = record.get("models", {}).values()
    if not any("initial_state" in m for m in models):
        return None
    return not any(m.get("initial_state") for m in models)


def fitted_dataset(record: dict, path: Path) -> FittedDataset:
    """What the compensation plan reads of a fit.json dataset ``record`` (read from
    ``path``): its name, input range, the recording's fastest input move, its fitted
    kinds and their held-out RMSE, whether its recording started at rest, its decision
    (:func:`record_decision`)."""
    models = record.get("models", {})
    stored = record.get("max_input_rate_counts_per_s")
    return FittedDataset(
        name=str(record.get("name")),
        where=str(path),
        input_range=tuple(float(x) for x in record["input_range_counts"]),
        recorded_rate=None if stored is None else float(stored),
        kinds=tuple(models),
        holdout={k: holdout_rmse(rec) for k, rec in models.items()},
        virgin=virgin_identified(record),
        decision=record_decision(record),
    )
