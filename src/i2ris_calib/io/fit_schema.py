"""Checks of the saved model files: fit.json (schema ``i2ris-calib.fit/1``, docs/fit.md)
and final_model.json (schema ``i2ris-calib.model/1``, docs/diagnosis.md); a fit saved by
``FitResult.save`` has a schema of its own (``i2ris-calib.fit-result/1``).

Every reader of these files goes through here (:func:`check_fit_doc`:
``io.fit.read_fit_json`` for ``compensate``, ``io.run_folder`` for ``report``;
:func:`check_model_doc`: ``io.fit.read_model_file`` for ``fit --model-file`` and
``compensate --model diagnosed``), so a hand-edited or damaged file is one
:class:`~i2ris_calib.errors.CalibError` naming the file, the dataset and the key
(``fit.json [yaw+]: datasets[0].models.egpi.params.a1 is null, not a finite number;
re-run 'fit' or restore the file``) before any work, never a Python error from deep
inside or a message that blames another input.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, NoReturn

from i2ris_calib.data.dataset import AXES
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.results import SCHEMA as SAVED_FIT
from i2ris_calib.hysteresis.codec import MODEL_SCHEMA
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.hysteresis.registry import BUILT_KINDS, model_for_kind

FIT_SCHEMA = "i2ris-calib.fit/1"
#: Model records a fit.json may hold besides the built kinds (a refitted saved model).
SAVED_KIND = DIAGNOSED

FIX_FIT = "re-run 'fit' or restore the file"
FIX_MODEL = "give the final_model.json written by 'diagnose' or restore the file"


def show(value: Any) -> str:
    """A JSON value as it reads in the file: ``null``, ``NaN``, ``'abc'``, ``[1, 2]``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def is_number(value: Any) -> bool:
    """An int or float, not a bool (JSON true/false)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class _Where:
    """Raises the one-line error of one file: ``<file> [<dataset>]: <key> <problem>; <fix>``."""

    def __init__(self, path: Path, fix: str) -> None:
        self.path = path
        self.fix = fix

    def fail(self, key: str, problem: str, dataset: Any = None) -> NoReturn:
        where = f" [{dataset}]" if isinstance(dataset, str) and dataset else ""
        raise CalibError(f"{self.path}{where}: {key} {problem}; {self.fix}")

    def number(
        self,
        obj: Mapping,
        name: str,
        key: str,
        dataset: Any = None,
        *,
        required: bool = False,
        nullable: bool = True,
        finite: bool = False,
        minimum: float | None = None,
    ) -> None:
        """``obj[name]`` (at ``key``) is a number: present when ``required``, not null
        unless ``nullable``, finite when ``finite``, ``>= minimum``."""
        if name not in obj:
            if required:
                self.fail(key, "is missing", dataset)
            return
        value = obj[name]
        if value is None:
            if not nullable:
                self.fail(key, "is null, not a finite number", dataset)
            return
        if not is_number(value):
            self.fail(key, f"= {show(value)} is not a number", dataset)
        if finite and not math.isfinite(value):
            self.fail(key, f"= {show(value)} is not a finite number", dataset)
        if minimum is not None and not value >= minimum:
            self.fail(key, f"= {show(value)} is below {minimum:g}", dataset)

    def numbers(
        self,
        obj: Any,
        key: str,
        dataset: Any = None,
        *,
        finite: bool = False,
        skip: Iterable[str] = (),
    ) -> None:
        """``obj`` (if present) is an object of numbers: finite ones when ``finite``,
        numbers or null otherwise; ``skip``: keys not checked."""
        if obj is None:
            return
        if not isinstance(obj, dict):
            self.fail(key, f"= {show(obj)} is not an object", dataset)
        for name in obj:
            if name not in skip:
                sub = f"{key}{name}" if name.startswith("[") else f"{key}.{name}"
                self.number(obj, name, sub, dataset, nullable=not finite, finite=finite)

    def texts(self, obj: Mapping, name: str, key: str, dataset: Any = None) -> None:
        """``obj[name]`` (if present and not null) is a list of strings."""
        value = obj.get(name)
        if value is not None and not (
            isinstance(value, list) and all(isinstance(x, str) for x in value)
        ):
            self.fail(key, f"= {show(value)} is not a list of texts", dataset)

    def params(self, params: Any, key: str, kind: Any, dataset: Any = None, n: Any = None) -> None:
        """A model's ``params``: an object of finite numbers; for a built kind, exactly
        that kind's parameters (a missing one would silently take its default) with ``n``
        operators when given (a kind whose parameter names depend on it: Maxwell slip)."""
        if not isinstance(params, dict):
            self.fail(key, f"= {show(params)} is not an object of parameter values", dataset)
        self.numbers(params, key, dataset, finite=True)
        if kind in BUILT_KINDS:
            names = model_for_kind(kind, **_operators(n)).names
            missing = [n for n in names if n not in params]
            if missing:
                self.fail(
                    key, f"has no {', '.join(missing)} (the {kind} model has {', '.join(names)})",
                    dataset,
                )  # fmt: skip
            extra = [n for n in params if n not in names]
            if extra:
                self.fail(
                    f"{key}.{extra[0]}",
                    f"is not a parameter of {kind} (it has {', '.join(names)})",
                    dataset,
                )


def check_fit_doc(doc: Any, path: str | Path, *, complete: bool = True) -> dict[str, Any]:
    """Check a fit.json document and return it; CalibError naming the file and the key.

    Every value present is checked: numbers where numbers belong (``rows``, ``bands``,
    ``stderr``, metrics: null allowed), every model parameter a finite number,
    ``input_range_counts`` two finite numbers with min < max, ``n_operators`` a whole
    number >= 1, ``deadband_counts`` a finite number >= 0, ``converged`` true/false.

    Parameters
    ----------
    doc : object
        The parsed JSON.
    path : path
        The file, for the messages.
    complete : bool
        Also require what a model is rebuilt from (``compensate``): the schema, ``axis``,
        each dataset's ``name`` and ``input_range_counts``, each model's ``params``
        (for a built kind exactly its parameters), model kinds of the registry.
        False (``report``, which shows what is there): only the ``datasets`` list (or
        the older single-dataset form with ``models`` at top level) and each dataset's
        ``models`` object are required.

    Returns
    -------
    dict
        ``doc``, unchanged.
    """
    p = Path(path)
    at = _Where(p, FIX_FIT)
    if not isinstance(doc, dict):
        raise CalibError(
            f"{p}: expected a JSON object at top level, got {type(doc).__name__}; {FIX_FIT}"
        )
    if (complete or "schema" in doc) and doc.get("schema") != FIT_SCHEMA:
        what = " (a file FitResult.save wrote: one fit)" if doc.get("schema") == SAVED_FIT else ""
        raise CalibError(
            f"{p}: schema is {doc.get('schema')!r}{what}, expected {FIT_SCHEMA!r}; re-run 'fit'"
        )
    if complete:
        if "axis" not in doc:
            at.fail("axis", "is missing")
        if doc["axis"] not in AXES:
            at.fail("axis", f"= {show(doc['axis'])} is not one of {', '.join(AXES)}")
    datasets = doc.get("datasets")
    if datasets is None:
        if complete or not isinstance(doc.get("models"), dict):
            raise CalibError(f"{p}: no 'datasets' list (schema {FIT_SCHEMA}); re-run 'fit'")
        datasets = [doc]  # older files: one dataset, its models at top level
    if not (isinstance(datasets, list) and all(isinstance(d, dict) for d in datasets)):
        raise CalibError(f"{p}: 'datasets' must be a list of objects; re-run 'fit'")
    for i, d in enumerate(datasets):
        _check_dataset(at, d, f"datasets[{i}]", complete)
    return doc


def _check_dataset(at: _Where, d: dict, key: str, complete: bool) -> None:
    name = d.get("name")
    if complete and not (isinstance(name, str) and name):
        at.fail(f"{key}.name", "is missing" if "name" not in d else f"= {show(name)} is not a name")
    label = name if isinstance(name, str) else None
    models = d.get("models")
    if not isinstance(models, dict):
        raise CalibError(f"{at.path}: {key} has no 'models' object; re-run 'fit'")
    at.numbers(d.get("rows"), f"{key}.rows", label)
    at.numbers(d.get("bands"), f"{key}.bands", label, skip=("derived",))
    for n in ("n_samples", "n_angles"):
        at.number(d, n, f"{key}.{n}", label)
    _check_range(at, d, f"{key}.input_range_counts", label, complete)
    if d.get("max_input_rate_counts_per_s") is not None:  # absent/null in older files
        at.number(
            d, "max_input_rate_counts_per_s", f"{key}.max_input_rate_counts_per_s", label,
            finite=True, minimum=0.0,
        )  # fmt: skip
    for kind, rec in models.items():
        _check_model(at, kind, rec, f"{key}.models.{kind}", label, complete)


def _check_range(at: _Where, d: dict, key: str, label: Any, complete: bool) -> None:
    """``input_range_counts``: [min, max], finite, min < max (the input range of the
    fit: compensate's command range)."""
    if "input_range_counts" not in d:
        if complete:
            at.fail(key, "is missing", label)
        return
    rng = d["input_range_counts"]
    if not (isinstance(rng, list) and len(rng) == 2):
        at.fail(key, f"= {show(rng)} is not [min, max]", label)
    at.numbers({"[0]": rng[0], "[1]": rng[1]}, key, label, finite=True)
    if not rng[0] < rng[1]:
        at.fail(key, f"= {show(rng)} is not ordered: min must be below max", label)


def _check_model(at: _Where, kind: str, rec: Any, key: str, label: Any, complete: bool) -> None:
    if rec is None and not complete:
        return
    if not isinstance(rec, dict):
        at.fail(key, f"= {show(rec)} is not an object", label)
    if complete and kind not in (*BUILT_KINDS, SAVED_KIND):
        at.fail(key, f"is not a model kind ({', '.join((*BUILT_KINDS, SAVED_KIND))})", label)
    if "params" in rec or complete:
        if rec.get("params") is None:
            at.fail(f"{key}.params", "is missing" if "params" not in rec else "is null", label)
        at.params(rec["params"], f"{key}.params", kind if complete else None, label,
                  rec.get("n_operators"))  # fmt: skip
    for part in ("stderr", "metrics", "holdout_metrics"):
        at.numbers(rec.get(part), f"{key}.{part}", label)
    conv = rec.get("converged")
    if conv is not None and not isinstance(conv, bool):
        at.fail(f"{key}.converged", f"= {show(conv)} is not true/false", label)
    n_op = rec.get("n_operators")
    if n_op is not None and not (is_number(n_op) and n_op >= 1 and float(n_op).is_integer()):
        at.fail(f"{key}.n_operators", f"= {show(n_op)} is not a whole number >= 1", label)
    at.number(rec, "deadband_counts", f"{key}.deadband_counts", label, nullable=False,
              finite=True, minimum=0.0)  # fmt: skip
    at.number(rec, "v_f", f"{key}.v_f", label)
    at.texts(rec, "warnings", f"{key}.warnings", label)
    at.texts(rec, "free", f"{key}.free", label)


def _operators(n: Any) -> dict[str, int]:
    """``{"n": n}`` for a whole number ``n >= 1`` (operators of the model), else ``{}``
    (the kind's default)."""
    if is_number(n) and n >= 1 and float(n).is_integer():
        return {"n": int(n)}
    return {}


def check_model_doc(obj: Any, path: str | Path) -> dict[str, Any]:
    """Check a final_model.json document (``diagnose``) and return it; CalibError naming
    the file and the key: ``base`` (``kind``: a built kind, ``params``: exactly its
    parameters, finite; ``n`` a whole number >= 1; ``deadband_counts`` finite >= 0;
    ``fixed`` names of its parameters), ``effects`` (each a ``name`` and finite
    ``params``), the repeated top-level ``params`` finite."""
    p = Path(path)
    at = _Where(p, FIX_MODEL)
    if not isinstance(obj, dict):
        raise CalibError(
            f"{p}: expected a JSON object at top level, got {type(obj).__name__}; {FIX_MODEL}"
        )
    if obj.get("schema") != MODEL_SCHEMA:
        raise CalibError(
            f"{p}: schema is {obj.get('schema')!r}, expected {MODEL_SCHEMA!r}; {FIX_MODEL}"
        )
    base = obj.get("base")
    if not isinstance(base, dict):
        at.fail("base", "is missing" if base is None else f"= {show(base)} is not an object")
    kind = base.get("kind")
    if kind not in BUILT_KINDS:
        at.fail("base.kind", f"= {show(kind)} is not one of {', '.join(BUILT_KINDS)}")
    if "params" not in base:
        at.fail("base.params", "is missing")
    at.params(base["params"], "base.params", kind, n=base.get("n"))
    n = base.get("n")
    if n is not None and not (is_number(n) and n >= 1 and float(n).is_integer()):
        at.fail("base.n", f"= {show(n)} is not a whole number >= 1")
    at.number(base, "deadband_counts", "base.deadband_counts", nullable=False, finite=True,
              minimum=0.0)  # fmt: skip
    at.texts(base, "fixed", "base.fixed")
    unknown = [f for f in base.get("fixed") or () if f not in base["params"]]
    if unknown:
        at.fail("base.fixed", f"names {unknown[0]!r}, not a parameter of the base model")
    effects = obj.get("effects", [])
    if not isinstance(effects, list):
        at.fail("effects", f"= {show(effects)} is not a list")
    for i, e in enumerate(effects):
        if not isinstance(e, dict):
            at.fail(f"effects[{i}]", f"= {show(e)} is not an object")
        if not isinstance(e.get("name"), str):
            at.fail(f"effects[{i}].name", "is missing" if "name" not in e else "is not a text")
        at.numbers(e.get("params", {}), f"effects[{i}].params", finite=True)
    at.numbers(obj.get("params"), "params", finite=True)
    return obj
