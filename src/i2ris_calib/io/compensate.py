"""``i2ris-calib compensate``: fit.json + target CSV -> COMMANDS.csv + compensate.json.

Formats are documented in docs/compensate.md (schema ``i2ris-calib.compensate/1``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.compensation import STATUS_NAMES, compensate
from i2ris_calib.compensation.inverse import forward
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.hysteresis.registry import INVERSE_KINDS
from i2ris_calib.io.atomic import atomic_path, write_json
from i2ris_calib.io.fit import read_fit_json, read_model_file
from i2ris_calib.io.outputs import claim_output_file
from i2ris_calib.io.provenance import provenance

SCHEMA = "i2ris-calib.compensate/1"
#: ``--model`` choices: the kinds with an inverse (registry) and ``"diagnosed"``
KINDS = (*INVERSE_KINDS, "diagnosed")
DATASETS = ("yaw+", "yaw-", "pitch+", "pitch-")

METHOD_NOTE = (
    "exact inversion of the stateful model sample by sample (one root find per branch "
    "region); where the model's output has a step (the paper EGPI's switch at v_f, a "
    "reversal jump) the command whose output is nearest the target is chosen; among "
    "commands that all meet the target (within tol_deg) the one that keeps the motion "
    "direction, then the smallest move; in a dead zone the largest move toward the "
    "target; a rate limit slews toward the unconstrained inverse; commands are whole "
    "counts (the better of the two neighbours of the chosen real-valued inverse, or the "
    "hold) and the predicted angles are the forward model evaluated over them"
)


def read_target(path: str | Path, axes: Sequence[str]) -> pd.DataFrame:
    """Read and validate a target CSV: ``time_s`` and ``<axis>_deg`` for every axis.

    One-line CalibError for: unreadable file, missing columns, non-numeric or NaN
    values, time not strictly increasing.
    """
    p = Path(path)
    if not p.is_file():
        raise CalibError(f"{p}: target file not found (a CSV with time_s and <axis>_deg)")
    try:
        df = pd.read_csv(p, skipinitialspace=True)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CalibError(f"{p}: not a readable CSV ({str(exc).splitlines()[0]})") from None
    df.columns = [str(c).strip() for c in df.columns]
    need = ["time_s", *[f"{a}_deg" for a in axes]]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise CalibError(
            f"{p}: missing column(s) {', '.join(missing)} (found: {', '.join(df.columns)}); "
            f"a target CSV has {', '.join(need)}"
        )
    if len(df) == 0:
        raise CalibError(f"{p}: no rows")
    for col in need:
        num = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~np.isfinite(num))
        if bad.size:
            raise CalibError(
                f"{p}: column '{col}' has {bad.size} missing/non-numeric value(s) "
                f"(first at line {bad[0] + 2}: {df[col].iloc[bad[0]]!r}); fill or remove them"
            )
        df[col] = num
    t = df["time_s"].to_numpy()
    d = np.flatnonzero(np.diff(t) <= 0)
    if d.size:
        raise CalibError(
            f"{p}: time_s must increase strictly; line {d[0] + 3} (t = {t[d[0] + 1]:g} s) "
            f"does not (previous t = {t[d[0]]:g} s)"
        )
    return df


def _dataset_record(doc: dict, name: str, path: Path) -> dict:
    names = [d.get("name") for d in doc.get("datasets", [])]
    for d in doc.get("datasets", []):
        if d.get("name") == name:
            return d
    raise CalibError(
        f"{path}: no dataset '{name}' (it has {', '.join(map(str, names)) or 'none'}); "
        "choose --dataset from those or fit that direction"
    )


def best_kind(record: dict) -> str:
    """The model kind of a fit.json dataset record with the lowest held-out RMSE
    (fitted-sample RMSE when nothing was held out)."""

    def score(rec):
        for key in ("holdout_metrics", "metrics"):
            x = (rec.get(key) or {}).get("rmse_deg")
            if x is not None and np.isfinite(x):
                return (0 if key == "holdout_metrics" else 1, float(x))
        return (2, np.inf)

    models = record.get("models", {})
    if not models:
        raise CalibError(f"dataset '{record.get('name')}' has no fitted models; re-run 'fit'")
    return min(models, key=lambda k: score(models[k]))


def load_model(doc: dict, record: dict, kind: str, path: Path, model_file: Path | None = None):
    """The fitted model ``kind`` of a fit.json dataset record, rebuilt."""
    models = record.get("models", {})
    if kind not in models:
        raise CalibError(
            f"{path}: dataset '{record['name']}' has no '{kind}' model (it has "
            f"{', '.join(models) or 'none'}); choose --model from those or re-run 'fit'"
        )
    rec = models[kind]
    if kind == "diagnosed":
        if model_file is None:
            raise CalibError(
                "--model diagnosed needs --model-file final_model.json (the diagnosed "
                "model's structure; fit.json holds its refitted values)"
            )

        base = read_model_file(model_file)
        names = [p.name for p in base.parameters]
        missing = [n for n in names if n not in rec["params"]]
        if missing:
            raise CalibError(
                f"{model_file}: its parameters {', '.join(missing)} are not in {path}'s "
                "diagnosed model; give the final_model.json that 'fit --model-file' used"
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


#: Share of the target outside the angles the model reaches above which compensate
#: says why, not only how many samples are unreachable (:func:`range_warning`).
OUTSIDE_SHARE = 0.5


def reachable_angles(model, v_limits: tuple[float, float], sign: float) -> tuple[float, float]:
    """(lowest, highest) angle (deg, the robot's sign: ``sign`` -1 for a ``-`` dataset)
    the model shows over its input range ``v_limits``: its output along a slow sweep of
    the whole range up and back down (both branches of the loop)."""
    up = np.linspace(v_limits[0], v_limits[1], 1001)
    v = np.concatenate([up, up[::-1]])
    y = sign * forward(model, v, np.arange(v.size, dtype=float))
    return float(np.min(y)), float(np.max(y))


def range_warning(
    name: str,
    kind: str,
    target_deg: np.ndarray,
    reach: tuple[float, float],
    tol_deg: float,
    reached: float,
) -> str | None:
    """Why a target is mostly unreachable (the likely mistake), or None.

    Said when most of the target lies outside the angles the model reaches (``reach``,
    deg in the robot's sign, :func:`reachable_angles`), or when most of it is not
    reached (``reached``: the share reached) and it is a sliver of the model's range in
    radian-sized numbers. Gives the target's range against the model's and, when that
    brings the target inside, the fix: degrees instead of radians, the other sign (the
    other motion direction's dataset), or both.
    """
    lo, hi = reach
    pad = max(float(tol_deg), 1e-6 * max(1.0, abs(lo), abs(hi)))

    def inside(x: np.ndarray) -> float:
        return float(np.mean((x >= lo - pad) & (x <= hi + pad)))

    x = np.asarray(target_deg, dtype=float)
    t_lo, t_hi = float(np.min(x)), float(np.max(x))
    outside = 1.0 - inside(x)
    radian_sized = max(abs(t_lo), abs(t_hi)) <= 2 * np.pi
    sliver = radian_sized and t_hi - t_lo < 0.05 * (hi - lo)
    if not (outside > OUTSIDE_SHARE or (1.0 - reached > OUTSIDE_SHARE and sliver)):
        return None
    other = name[:-1] + ("-" if name.endswith("+") else "+")
    sign_fix = f"give --dataset {other} (the other motion direction) or negate the target"
    deg = np.degrees(x)
    in_deg = f"{np.degrees(t_lo):.3g} to {np.degrees(t_hi):.3g} deg"
    fixes = []
    if outside > OUTSIDE_SHARE:
        fixes.append((inside(-x), f"the target has the other sign: {sign_fix}"))
    if radian_sized:
        fixes += [
            (inside(deg), f"if the target is in radians, convert it to degrees ({in_deg})"),
            (inside(-deg), f"the target looks like radians ({in_deg}) of the other sign: "
                           f"convert it to degrees and {sign_fix}"),
        ]  # fmt: skip
    share, fix = max(fixes, key=lambda f: f[0], default=(0.0, ""))
    if share < 0.9:
        fix = "give a target within the model's angles, or fit recordings that reach the target's"
    if outside > OUTSIDE_SHARE:
        what = f"{outside:.0%} of the target lies outside the angles the model reaches"
    else:
        what = (
            f"{1.0 - reached:.0%} of the target is unreachable, and it is a sliver of the "
            "model's angles"
        )
    return (
        f"{name} ({kind}): {what}: the target spans {t_lo:.3g} to {t_hi:.3g} deg, the model "
        f"{lo:.3g} to {hi:.3g} deg; {fix}"
    )


def compensate_files(
    fit_paths: Sequence[str | Path],
    datasets: Sequence[str],
    target: str | Path,
    out: str | Path,
    config=None,
    model: str | None = None,
    max_counts_per_s: float | None = None,
    start_counts: float | None = None,
    model_file: str | Path | None = None,
) -> dict[str, Any]:
    """Command body of ``i2ris-calib compensate``; returns the compensate.json document.

    Parameters
    ----------
    fit_paths : sequence of path
        fit.json file(s); each dataset is looked up in the one whose axis matches.
    datasets : sequence of str
        ``yaw+``, ``yaw-``, ``pitch+``, ``pitch-``: at most one per axis.
    target : path
        Target CSV (``time_s``, ``<axis>_deg`` per axis).
    out : path
        COMMANDS.csv to write; compensate.json is written beside it.
    model : str, optional
        egpi, egpi_c, gpi or diagnosed; default the best held-out model.
    max_counts_per_s : float, optional
        Motor rate limit (counts/s).
    start_counts : float, optional
        Signed encoder counts before the first target sample (e.g. 0 at rest).
    model_file : path, optional
        final_model.json (``--model diagnosed``).
    """
    if model is not None and model not in KINDS:
        raise CalibError(f"--model must be one of {', '.join(KINDS)}, got '{model}'")
    if not fit_paths:
        raise CalibError("give at least one fit.json")
    if not datasets:
        raise CalibError("give --dataset (yaw+, yaw-, pitch+ or pitch-)")
    for name in datasets:
        if name not in DATASETS:
            raise CalibError(f"--dataset must be one of {', '.join(DATASETS)}, got '{name}'")
    axes = [n[:-1] for n in datasets]
    if len(set(axes)) != len(axes):
        raise CalibError("give at most one --dataset per axis (the direction of each motor)")
    out = Path(out)
    if out.suffix.lower() != ".csv":
        raise CalibError(f"--out {out}: give the COMMANDS.csv file to write (ending in .csv)")
    claim_output_file(
        out,
        [*fit_paths, target, *([model_file] if model_file else [])],
        companions=[out.with_name("compensate.json")],
    )
    docs = [(Path(p), read_fit_json(p)) for p in fit_paths]
    frame = read_target(target, axes)
    t = frame["time_s"].to_numpy()
    cols: dict[str, Any] = {"time_s": t}
    axes_doc: dict[str, Any] = {}
    reach_all = np.ones(t.size, dtype=bool)
    for name, axis in zip(datasets, axes, strict=True):
        found = [(p, d) for p, d in docs if d.get("axis") == axis]
        if not found:
            raise CalibError(
                f"no fit.json for the {axis} axis among {', '.join(str(p) for p, _ in docs)}; "
                f"give the {axis} fit.json too"
            )
        path, doc = found[0]
        record = _dataset_record(doc, name, path)
        kind = model or best_kind(record)
        fitted = load_model(
            doc, record, kind, path, None if model_file is None else Path(model_file)
        )
        sign = -1.0 if name.endswith("-") else 1.0
        lo, hi = (float(x) for x in record["input_range_counts"])
        lo = min(lo, 0.0)
        v0 = None
        if start_counts is not None:
            v0 = max(sign * float(start_counts), 0.0)
        try:
            res = compensate(
                fitted,
                sign * frame[f"{axis}_deg"].to_numpy(),
                t,
                v_limits=(lo, hi),
                max_rate=max_counts_per_s,
                quantum=1.0,
                v_initial=None if v0 is None else float(np.clip(v0, lo, hi)),
            )
        except CalibError as exc:
            raise CalibError(f"{target} [{name}]: {exc}") from None
        enc = np.rint(sign * res.commands).astype(np.int64)
        cols[f"enc_{axis}"] = enc
        cols[f"predicted_{axis}_deg"] = sign * res.predicted_deg
        reach_all &= res.reachable
        if len(datasets) > 1:
            cols[f"reachable_{axis}"] = res.reachable.astype(int)
        summ = res.summary()
        bad = np.flatnonzero(~res.reachable)
        reach = reachable_angles(fitted, (lo, hi), sign)
        warn = range_warning(
            name, kind, frame[f"{axis}_deg"].to_numpy(), reach, res.tol_deg,
            float(res.reachable.mean()),
        )  # fmt: skip
        axes_doc[axis] = {
            "dataset": name,
            "fit_json": str(path),
            "model": kind,
            "params": record["models"][kind]["params"],
            "input_range_counts": [lo, hi],
            "max_counts_per_s": max_counts_per_s,
            "start_counts": start_counts,
            "delay_s": res.delay_s,
            "tol_deg": res.tol_deg,
            **summ,
            "unreachable_first_times_s": [float(t[i]) for i in bad[:20]],
            "status_codes": {str(k): v for k, v in STATUS_NAMES.items()},
            "reachable_deg": list(reach),
            "warnings": [] if warn is None else [warn],
        }
    cols["reachable"] = reach_all.astype(int)
    table = pd.DataFrame(cols)
    inputs = [*(p for p, _ in docs), Path(target), *([Path(model_file)] if model_file else [])]
    doc_out = {
        "schema": SCHEMA,
        "commands_csv": out.name,
        "method": METHOD_NOTE,
        "axes": axes_doc,
        "provenance": provenance(inputs, config),
    }
    # both files or neither: compensate.json is renamed into place after the CSV
    with atomic_path(out.with_name("compensate.json")) as tmp_json:
        write_json(tmp_json, doc_out)
        with atomic_path(out) as tmp_csv:
            table.to_csv(tmp_csv, index=False, float_format="%.10g")
    return doc_out
