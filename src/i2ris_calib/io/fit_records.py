"""Reading what compensation needs from a fit.json (docs/formats.md, fit.json): a
dataset's record, its models rebuilt, and the motor
rate limit the recording supports. Used by ``compensate`` and the online
:class:`~i2ris_calib.io.online.Compensator`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.decision import Decision
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.io.fit import read_model_file

__all__ = [
    "API_NAMES",
    "CLI_NAMES",
    "FALLBACK_RANGE_SHARE_PER_S",
    "dataset_names",
    "dataset_record",
    "decided_kind",
    "record_decision",
    "holdout_rmse",
    "load_model",
    "rate_limit",
]

#: Rate limit when fit.json does not store the recording's fastest input move (older
#: files): this share of the fitted input range per second
FALLBACK_RANGE_SHARE_PER_S = 0.1

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
        return model_from_params(
            kind,
            rec["params"],
            int(rec.get("n_operators") or 30),
            float(rec.get("deadband_counts", 2.0)),
        )
    except CalibError as exc:
        raise CalibError(
            f"{path}: dataset '{record['name']}', model '{kind}': {exc} (re-run 'fit' or "
            "restore the file)"
        ) from None


def rate_limit(
    record: dict,
    explicit: float | None,
    configured: float,
    range_counts: float,
    names: dict = CLI_NAMES,
) -> tuple[float, str, str | None]:
    """(rate limit in counts/s, where it comes from, a warning line or None).

    ``explicit`` (``--max-counts-per-s``) wins, then ``configured`` (``[compensate]
    max_counts_per_s``, 0 = not set); ``inf`` means no limit. Otherwise the fastest
    input move of the fit's recording (fit.json ``max_input_rate_counts_per_s``); a
    fit.json without it (older files) falls back to :data:`FALLBACK_RANGE_SHARE_PER_S`
    of the fitted input range per second, with a warning.
    """
    for value, source in ((explicit, names["rate"].rstrip("=")),
                          (configured or None, "[compensate] max_counts_per_s")):  # fmt: skip
        if value is not None:
            if not float(value) > 0:
                raise CalibError(f"{source} = {value:g}: give a rate > 0 counts/s (inf: no limit)")
            return float(value), source, None
    stored = record.get("max_input_rate_counts_per_s")
    if stored is not None and float(stored) > 0:
        return (
            float(stored),
            "fit.json max_input_rate_counts_per_s (the recording's fastest move)",
            None,
        )
    rate = FALLBACK_RANGE_SHARE_PER_S * range_counts
    return (
        rate,
        "fallback",
        (
            f"{record.get('name')}: fit.json has no max_input_rate_counts_per_s (written by an "
            f"older 'fit'); rate limit {rate:g} counts/s ({FALLBACK_RANGE_SHARE_PER_S:g} of the "
            f"fitted input range per second): re-run 'fit' or give {names['rate']}"
        ),
    )


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


def decided_kind(record: dict, refusal, where: str) -> tuple[str, str]:
    """(kind, note) of the dataset record's recommended model for an entry point that
    cannot use every kind (``refusal(kind)``: why not, None when it can;
    :meth:`Decision.model_for`); ``note`` says which model it uses instead and why
    (empty: the recommended one). A one-line CalibError (``where``: the file and
    dataset) when it can use none."""
    kind, note = record_decision(record).model_for(refusal)
    if kind is None:
        raise CalibError(f"{where}: {note}")
    return kind, note
