"""A run folder (or a ``fit`` output folder) read for ``i2ris-calib report``: every
stage output in a :class:`~i2ris_calib.report.data.RunData` (docs/report.md).

Reading is strict about what is there and lenient about what is not: a missing
stage output is recorded in :attr:`RunData.absent` and stated in the report; a
present but malformed JSON/CSV is a one-line :class:`CalibError` naming the file.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from i2ris_calib.data.dataset import AXES
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.registry import ALL_KINDS
from i2ris_calib.io.fit_schema import check_fit_doc
from i2ris_calib.report.data import CompensationData, DiagnosisData, FitData, RunData

ANGLES_COLUMNS = {"time_s": True, "yaw_deg": True, "pitch_deg": True, "status": False}
SYNCED_COLUMNS = {
    "time_s": True,
    "enc_yaw": True,
    "enc_pitch": True,
    "yaw_deg": True,
    "pitch_deg": True,
}
PREDICTION_COLUMNS = {
    "dataset": False,
    "time_s": True,
    "v": True,
    "theta_deg": True,
    "split": False,
}
#: One column per model kind a fit.json may hold (the registry): gpi_deg, egpi_deg,
#: egpi_c_deg, agpi_deg, agpi_coupled_deg, diagnosed_deg
MODEL_COLUMNS = tuple(f"{k}_deg" for k in ALL_KINDS)
OPTIONAL_NUMERIC = (
    "reproj_err_px",
    *MODEL_COLUMNS,
    *(c.removesuffix("_deg") + "_sd_deg" for c in MODEL_COLUMNS),
)
SPLITS = ("fit", "holdout", "other")


class _Reader:
    """Reads files of one run folder, remembering which exist and which do not."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.absent: dict[str, str] = {}
        self.read: list[Path] = []

    def path(self, label: str) -> Path | None:
        p = self.root / label
        if not p.is_file():
            self.absent[label] = "not found"
            return None
        self.read.append(p)
        return p

    def json(self, label: str) -> dict[str, Any] | None:
        p = self.path(label)
        return None if p is None else read_json_object(p)

    def csv(self, label: str, columns: Mapping[str, bool]) -> pd.DataFrame | None:
        p = self.path(label)
        if p is None:
            return None
        frame = read_csv_checked(p, columns)
        if frame.empty:
            self.absent[label] = "present but has no data rows"
            return None
        return frame


def read_json_object(path: Path) -> dict[str, Any]:
    """Parse a JSON file whose top level is an object; CalibError naming the file otherwise."""
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CalibError(
            f"{path}: malformed JSON ({exc}); re-run the stage that writes it"
        ) from None
    except OSError as exc:
        raise CalibError(f"{path}: cannot read ({exc.strerror}); check its permissions") from None
    if not isinstance(obj, dict):
        raise CalibError(
            f"{path}: expected a JSON object at top level, got {type(obj).__name__}; "
            "re-run the stage that writes it"
        )
    return obj


def read_csv_checked(path: Path, columns: Mapping[str, bool]) -> pd.DataFrame:
    """Read a CSV and check required columns (``name -> must be numeric``).

    Optional numeric columns (:data:`OPTIONAL_NUMERIC`) are checked when present.
    Raises CalibError naming the file and the column on any problem.
    """
    try:
        frame = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise CalibError(
            f"{path}: malformed CSV ({msg}); re-run the stage that writes it"
        ) from None
    except OSError as exc:
        raise CalibError(f"{path}: cannot read ({exc.strerror}); check its permissions") from None
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise CalibError(
            f"{path}: missing column(s) {', '.join(missing)} (has: {', '.join(map(str, frame.columns))}); "
            "see docs/report.md for the expected columns"
        )
    numeric = [c for c, is_num in columns.items() if is_num] + [
        c for c in OPTIONAL_NUMERIC if c in frame.columns
    ]
    for c in numeric:
        if not pd.api.types.is_numeric_dtype(frame[c]):
            converted = pd.to_numeric(frame[c], errors="coerce")
            bad = frame[c][converted.isna() & frame[c].notna()]
            if len(bad):
                raise CalibError(
                    f"{path}: column '{c}' has non-numeric value {bad.iloc[0]!r} "
                    f"(row {int(bad.index[0]) + 2}); re-run the stage that writes it"
                )
            frame[c] = converted
    return frame


def check_fit_json(fit: Mapping[str, Any], path: Path) -> None:
    """Check a fit.json with the one fit.json check every reader uses
    (:func:`~i2ris_calib.io.fit_schema.check_fit_doc`; what is there, as the report
    shows what it finds); CalibError naming the file and the key."""
    check_fit_doc(fit, path, complete=False)


def check_predictions(pred: pd.DataFrame, path: Path) -> None:
    """A predictions.csv has a model column and only known ``split`` values; CalibError else."""
    if not set(MODEL_COLUMNS) & set(pred.columns):
        raise CalibError(
            f"{path}: no model column (none of {', '.join(MODEL_COLUMNS)}); re-run 'fit'"
        )
    split = pred["split"]
    bad = split[~split.isin(SPLITS)]
    if len(bad):
        raise CalibError(
            f"{path}: column 'split' has value {bad.iloc[0]!r} (row {int(bad.index[0]) + 2}); "
            f"expected one of {', '.join(SPLITS)}; re-run 'fit'"
        )


def png_paths(obj: Any) -> list[str]:
    """Every string value ending in ``.png`` in a JSON structure, in document order, unique."""
    out: list[str] = []

    def walk(x: Any) -> None:
        if isinstance(x, str) and x.lower().endswith(".png") and x not in out:
            out.append(x)
        elif isinstance(x, Mapping):
            for v in x.values():
                walk(v)
        elif isinstance(x, list):
            for v in x:
                walk(v)

    walk(obj)
    return out


def _axis_order(names: Iterable[str]) -> list[str]:
    names = set(names)
    return [a for a in AXES if a in names] + sorted(names - set(AXES))


def _load_fits(r: _Reader) -> tuple[FitData, ...]:
    fit_root = r.root / "fit"
    found = [p.name for p in fit_root.iterdir() if p.is_dir()] if fit_root.is_dir() else []
    fits = []
    for axis in _axis_order(set(found) | set(AXES)):
        label = f"fit/{axis}/fit.json"
        fit = r.json(label)
        if fit is None:
            continue
        check_fit_json(fit, r.root / label)
        pred = r.csv(f"fit/{axis}/predictions.csv", PREDICTION_COLUMNS)
        if pred is not None:
            check_predictions(pred, r.root / f"fit/{axis}/predictions.csv")
        fits.append(FitData(axis=axis, fit=fit, predictions=pred))
    return tuple(fits)


def _load_compensation(r: _Reader) -> CompensationData | None:
    """``compensate/`` (optional: only when ``run`` had a ``[compensate] target``)."""
    if not (r.root / "compensate" / "compensate.json").is_file():
        return None
    doc = r.json("compensate/compensate.json")
    commands = r.csv("compensate/commands.csv", {"time_s": True, "reachable": True})
    if doc is None or commands is None:
        return None
    target = None
    if (r.root / "compensate" / "target.csv").is_file():
        target = r.csv("compensate/target.csv", {"time_s": True})
    return CompensationData(doc=doc, commands=commands, target=target)


def _load_diagnoses(r: _Reader) -> tuple[DiagnosisData, ...]:
    root = r.root / "diagnose"
    if not root.is_dir():
        return ()
    out = []
    for axis in _axis_order(p.name for p in root.iterdir() if (p / "diagnosis.json").is_file()):
        folder = root / axis
        diag = r.json(f"diagnose/{axis}/diagnosis.json")
        md_path = folder / "diagnosis.md"
        markdown = None
        if md_path.is_file():
            r.read.append(md_path)
            try:
                markdown = md_path.read_text(encoding="utf-8")
            except UnicodeDecodeError:
                raise CalibError(f"{md_path}: not UTF-8 text; re-run 'diagnose'") from None
        images, missing = {}, []
        for rel in png_paths(diag):
            p = (folder / rel).resolve()
            if p.is_file() and folder.resolve() in p.parents:
                r.read.append(p)
                images[rel] = p.read_bytes()
            else:
                missing.append(rel)
        out.append(DiagnosisData(axis, diag, markdown, images, tuple(missing)))
    return tuple(out)


def load_run(run_dir: str | Path) -> tuple[RunData, list[Path]]:
    """Read every stage output of a run folder.

    Parameters
    ----------
    run_dir : path
        Folder laid out as in docs/report.md (track/, sync/, fit/<axis>/, diagnose/<axis>/),
        or a ``fit`` output folder (fit.json + predictions.csv, :func:`load_fit_folder`).

    Returns
    -------
    run : RunData
        Parsed contents; absent outputs listed in ``run.absent``.
    inputs : list of Path
        Files actually read (for the provenance hashes).
    """
    root = Path(run_dir)
    if not root.is_dir():
        raise CalibError(f"run folder not found: {root} (give the folder written by 'run')")
    if is_fit_folder(root):
        return load_fit_folder(root)
    _check_is_run_folder(root)
    r = _Reader(root)
    angles = r.csv("track/angles.csv", ANGLES_COLUMNS)
    track = r.json("track/track.json")
    sync = r.json("sync/sync.json")
    synced = r.csv("sync/synced.csv", SYNCED_COLUMNS)
    fits = _load_fits(r)
    diagnoses = _load_diagnoses(r)
    compensation = _load_compensation(r)
    run = RunData(
        name=root.resolve().name,
        angles=angles,
        track=track,
        sync=sync,
        synced=synced,
        fits=fits,
        diagnoses=diagnoses,
        compensation=compensation,
        absent=dict(r.absent),
    )
    return run, r.read


STAGE_FOLDERS = ("track", "sync", "fit", "diagnose", "compensate")
#: The files of a ``fit`` output folder the report reads.
FIT_FILES = ("fit.json", "predictions.csv")


def is_fit_folder(root: Path) -> bool:
    """True for a ``fit`` output folder: ``fit.json`` in it and no stage folder."""
    return (root / "fit.json").is_file() and not any((root / s).is_dir() for s in STAGE_FOLDERS)


def load_fit_folder(fit_dir: str | Path) -> tuple[RunData, list[Path]]:
    """Read a ``fit`` output folder (fit.json, predictions.csv) as a model-only run.

    Returns
    -------
    run : RunData
        ``fit_only`` True, one FitData named by fit.json's ``axis`` (else the folder
        name); a missing predictions.csv is listed in ``run.absent``.
    inputs : list of Path
        Files read.
    """
    root = Path(fit_dir)
    r = _Reader(root)
    fit = r.json("fit.json")
    if fit is None:  # pragma: no cover - is_fit_folder checked it
        raise CalibError(f"{root}: no fit.json; give a folder written by 'fit'")
    check_fit_json(fit, root / "fit.json")
    pred = r.csv("predictions.csv", PREDICTION_COLUMNS)
    if pred is not None:
        check_predictions(pred, root / "predictions.csv")
    axis = str(fit.get("axis") or root.resolve().name)
    run = RunData(
        name=root.resolve().name,
        fits=(FitData(axis=axis, fit=fit, predictions=pred),),
        absent=dict(r.absent),
        fit_only=True,
    )
    return run, r.read


def _check_is_run_folder(root: Path) -> None:
    """CalibError when ``root`` holds no stage folder: the parent of run folders (say
    which to give), an unrelated or an empty folder (nothing to report; the same error
    every time, whatever a refused earlier call left)."""
    if any((root / s).is_dir() for s in STAGE_FOLDERS):
        return
    runs = sorted(
        p.name
        for p in root.iterdir()
        if p.is_dir() and any((p / s).is_dir() for s in STAGE_FOLDERS)
    )
    if runs:
        raise CalibError(
            f"{root} holds runs, not one run: give one of them, e.g. 'report {root / runs[0]}' "
            f"({len(runs)} run(s): {', '.join(runs[:5])}{', ...' if len(runs) > 5 else ''})"
        )
    raise CalibError(
        f"{root}: no track/, sync/, fit/ or diagnose/ folder, nothing to report; give a run "
        "folder written by 'run' (or a folder written by 'fit')"
    )
