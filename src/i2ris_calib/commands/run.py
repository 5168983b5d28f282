"""``i2ris-calib run``: track -> sync -> fit [-> diagnose] -> report for one or more sessions.

``[run] diagnose = true`` adds a diagnose stage per axis and dataset the default fit
fits (``<run>/diagnose/<axis><direction>/``, ``--start auto``): ``+`` and ``-`` on the
paper's protocol, ``±`` when the fit models the axis over its signed input (the input
crosses zero or the recording starts mid-loop); the others record why they did not run
in ``skipped.json``. Stamped like the others.

Each stage writes its outputs atomically and then a stamp file ``.stamp.json`` in its
folder recording the SHA-256 of its inputs, its config section and the package
version. A stage is skipped when its stamp matches; the stamp is removed before a
stage starts, so an interrupted stage is always redone (no half-written output is
reused). Sessions run in parallel processes.
"""

from __future__ import annotations

import functools
import hashlib
import json
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
from rich.console import Console

from i2ris_calib import __version__
from i2ris_calib.commands.compensate import compensate_files
from i2ris_calib.commands.diagnose import OUTPUTS as DIAGNOSE_OUTPUTS
from i2ris_calib.commands.diagnose import diagnose_dataset
from i2ris_calib.commands.fit import fit_files
from i2ris_calib.commands.report import write_report
from i2ris_calib.commands.sync import sync_session
from i2ris_calib.commands.track import track_session
from i2ris_calib.config import PipelineConfig
from i2ris_calib.data.dataset import AXES
from i2ris_calib.diagnosis.workflow import check_dataset
from i2ris_calib.errors import CalibError
from i2ris_calib.io.atomic import write_bytes, write_json
from i2ris_calib.io.config_io import dataclass_to_dict
from i2ris_calib.io.csv_file import read_csv_header
from i2ris_calib.io.encoders import encoder_log_path
from i2ris_calib.io.outputs import check_not_input, check_out_path, output_dir
from i2ris_calib.io.provenance import file_sha256
from i2ris_calib.io.session import check_cameras, load_session, session_file
from i2ris_calib.io.synced import frame_datasets, frames_for_fit, read_frames
from i2ris_calib.io.video import input_files
from i2ris_calib.session import SessionSpec

STAMP = ".stamp.json"


@dataclass(frozen=True)
class Stage:
    """One pipeline stage of one session: where it writes and what it depends on."""

    name: str
    out_dir: Path
    inputs: tuple[Path, ...]
    config: Any
    action: Callable[[], str | None]  # None, or what happened instead of a run ("skipped: ...")


def stamp_of(stage: Stage) -> dict[str, Any]:
    """What a stage's outputs were computed from (inputs' hashes, config, version)."""
    cfg = json.dumps(dataclass_to_dict(stage.config), sort_keys=True, default=str)
    return {
        "stage": stage.name,
        "version": __version__,
        "config_sha256": hashlib.sha256(cfg.encode()).hexdigest(),
        "inputs": {str(p): cached_sha256(p) for p in expand_inputs(stage.inputs)},
    }


def expand_inputs(paths: tuple[Path, ...]) -> list[Path]:
    """Files behind ``paths``: a folder stands for every file below it (dotfiles excluded)."""
    files: list[Path] = []
    for p in paths:
        if p.is_dir():
            files.extend(
                sorted(
                    f
                    for f in p.rglob("*")
                    if f.is_file()
                    and not any(part.startswith(".") for part in f.relative_to(p).parts)
                )
            )
        elif p.is_file():
            files.append(p)
    return files


@functools.lru_cache(maxsize=1 << 16)  # every image of an image-sequence video
def _sha256_keyed(path: str, size: int, mtime_ns: int) -> str:
    return file_sha256(path)


def cached_sha256(path: Path) -> str:
    """SHA-256 of a file, computed once per (path, size, mtime) in this process."""
    st = path.stat()
    return _sha256_keyed(str(path), st.st_size, st.st_mtime_ns)


def is_up_to_date(stage: Stage) -> bool:
    """True when the stage's stamp exists and matches its current inputs and config."""
    path = stage.out_dir / STAMP
    if not path.is_file():
        return False
    try:
        return json.loads(path.read_text()) == stamp_of(stage)
    except (OSError, json.JSONDecodeError):
        return False


def run_stage(stage: Stage, force: bool) -> str:
    """Run ``stage`` unless up to date; returns ``"ran"``, ``"up to date"``, or what the
    stage said instead (a diagnose stage that does not apply: ``"skipped: <why>"``;
    up to date: ``"up to date (skipped: <why>)"``)."""
    if not force and is_up_to_date(stage):
        why = skipped_reason(stage.out_dir)
        return "up to date" + (f" (skipped: {why})" if why else "")
    (stage.out_dir / STAMP).unlink(missing_ok=True)
    said = stage.action()
    write_json(stage.out_dir / STAMP, stamp_of(stage))
    return said or "ran"


def skipped_reason(out_dir: Path) -> str | None:
    """The reason in ``out_dir/skipped.json`` (a diagnose stage that did not apply), or None."""
    try:
        reason = json.loads((out_dir / "skipped.json").read_text(encoding="utf-8"))["reason"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return str(reason)


def stage_input_files(
    session: Path, spec: SessionSpec | None = None
) -> dict[str, tuple[Path, ...]]:
    """The files of a session that the ``track`` and ``sync`` stages read, by stage.

    Only files session.toml names: per camera its video (an image sequence: its
    images), timestamps and, for ``model = "pinhole"``, calibration file (``track``);
    the encoder log (a ROS2 bag folder: its files; ``sync``). Anything else in the
    session folder (a target CSV, notes, ``truth/``) is no input. A named file that
    does not exist is left out: the stage that reads it names it.

    Parameters
    ----------
    session : Path
        Session folder.
    spec : SessionSpec, optional
        Its session.toml, when already loaded.

    Returns
    -------
    dict
        ``{"track": paths, "sync": paths}``.
    """
    spec = spec if spec is not None else load_session(session)
    track: list[Path] = []
    for cam in spec.cameras.values():
        track += _named_files(session, cam.video, video=True)
        track += _named_files(session, cam.timestamps)
        if cam.model == "pinhole":
            track += _named_files(session, cam.calibration)
    return {"track": tuple(track), "sync": tuple(_named_files(session, spec.encoder.file))}


def _named_files(session: Path, relative: str, video: bool = False) -> list[Path]:
    """The files behind one path of session.toml (none when empty or missing)."""
    if not relative:
        return []
    p = session / relative
    if p.is_dir() and video:
        try:
            return input_files(p)
        except CalibError:  # not an image sequence: track names the problem
            pass
    return expand_inputs((p,))


def session_settings(spec: SessionSpec) -> dict[str, dict[str, Any]]:
    """The session.toml values each of ``track`` and ``sync`` reads (part of their stamps).

    ``track``: ``[cameras.*]`` and ``[marker]``; ``sync``: ``[encoder]``. ``name`` only
    names the run folder and ``notes`` is free text: neither is in.
    """
    return {
        "track": {
            "cameras": dataclass_to_dict(spec.cameras),
            "marker": dataclass_to_dict(spec.marker),
        },
        "sync": {"encoder": dataclass_to_dict(spec.encoder)},
    }


def axis_moves(synced_csv: Path, axis: str, min_span_counts: float = 1.0) -> bool:
    """True when the synced data contains motion of ``axis`` (its encoder changes)."""
    col = f"enc_{axis}"
    enc = pd.read_csv(synced_csv, usecols=lambda c: c == col)
    return col in enc and float(enc[col].max() - enc[col].min()) >= min_span_counts


#: The datasets a ``run`` diagnose stage may diagnose per axis; the default fit's choice
#: (:func:`~i2ris_calib.commands.fit.datasets_for_fit`) decides at run time which run
RUN_DIRECTIONS = ("+", "-", "±")


def session_stages(session: Path, run_dir: Path, config: PipelineConfig) -> list[Stage]:
    """The ordered stages for one session writing under ``run_dir``: track, sync, a fit
    per axis, the diagnose stages (``[run] diagnose``), compensate (``[compensate]
    target``), report."""
    synced = run_dir / "sync" / "synced.csv"
    stages = _track_sync_stages(session, run_dir, config)
    stages += _fit_stages(synced, run_dir, config)
    if config.run.diagnose:
        stages += _diagnose_stages(synced, run_dir, config)
    if config.compensate.target:
        target = compensation_target(session, config.compensate.target)
        comp_dir = run_dir / "compensate"
        stages.append(
            Stage(
                "compensate",
                comp_dir,
                (target, run_dir / "fit"),
                config.compensate,
                lambda: compensate_run(run_dir, target, comp_dir, config),
            )
        )
    folders = ("track", "sync", "fit", "diagnose", "compensate")
    stages.append(
        Stage(
            "report",
            run_dir / "report",
            tuple(run_dir / f for f in folders),
            config.report,
            lambda: write_report(run_dir, run_dir / "report", config),
        )
    )
    return stages


def _track_sync_stages(session: Path, run_dir: Path, config: PipelineConfig) -> list[Stage]:
    """The track and sync stages (their inputs: the files session.toml names)."""
    track_dir, sync_dir = run_dir / "track", run_dir / "sync"
    angles = track_dir / "angles.csv"
    spec = load_session(session)
    named, settings = stage_input_files(session, spec), session_settings(spec)
    return [
        Stage(
            "track",
            track_dir,
            named["track"],
            (config.track, settings["track"]),
            lambda: track_session(session, track_dir, config),
        ),
        Stage(
            "sync",
            sync_dir,
            (*named["sync"], angles),
            # the model-based clock estimate refits with [fit]
            (config.sync, config.fit, settings["sync"]),
            lambda: sync_session(session, angles, sync_dir, config),
        ),
    ]


def _fit_stages(synced: Path, run_dir: Path, config: PipelineConfig) -> list[Stage]:
    """A fit stage per axis (an axis that does not move is left unfitted)."""
    stages = []
    for axis in AXES:
        fit_dir = run_dir / "fit" / axis

        def fit_axis(axis: str = axis, fit_dir: Path = fit_dir) -> None:
            if axis_moves(synced, axis):
                fit_files([synced], axis=axis, model="all", out=fit_dir, config=config)

        stages.append(Stage(f"fit {axis}", fit_dir, (synced,), config.fit, fit_axis))
    return stages


def _diagnose_stages(synced: Path, run_dir: Path, config: PipelineConfig) -> list[Stage]:
    """A diagnose stage per axis and :data:`RUN_DIRECTIONS` entry
    (:func:`diagnose_direction` decides at run time which run)."""
    stages = []
    for axis in AXES:
        for direction in RUN_DIRECTIONS:
            out = run_dir / "diagnose" / f"{axis}{direction}"

            def diagnose_one(axis: str = axis, direction: str = direction, out: Path = out):
                return diagnose_direction(synced, axis, direction, out, config)

            stages.append(
                Stage(
                    f"diagnose {axis}{direction}",
                    out,
                    (synced,),
                    (config.fit, config.diagnose),
                    diagnose_one,
                )
            )
    return stages


def diagnose_direction(
    synced: Path, axis: str, direction: str, out: Path, config: PipelineConfig
) -> str | None:
    """The diagnose stage of one axis and direction (``--start auto``).

    ``direction`` is diagnosed when the default fit fits it (the dataset of
    :func:`~i2ris_calib.commands.fit.datasets_for_fit`: ``±`` on a signed choice, else
    ``+`` and ``-``). A direction it does not fit and data the diagnosis cannot work
    with (the axis does not move in this direction,
    or fewer than the minimum loading cycles, see
    :func:`~i2ris_calib.diagnosis.workflow.check_dataset`) do not stop the run:
    ``out/skipped.json`` records why and the report shows the other diagnoses.
    Returns None when diagnosed, else ``"skipped: <why>"`` (what ``run`` prints), or
    ``"ran; fit.json's <dataset> <kind> replaced: ..."`` when the diagnosis found a
    lower cost of a model of the run's fit (replaced: :func:`~i2ris_calib.commands.
    diagnose.diagnose_dataset`), before compensate and report read it.
    """
    try:
        if not axis_moves(synced, axis):
            raise CalibError(f"{axis} does not move in {synced}")
        frames = read_frames([synced], axis)  # read and validated once
        found, choice = frames_for_fit(frames, axis, config.fit)
        if (direction == "±") != choice.signed:
            fitted = f"{axis}±" if choice.signed else f"{axis}+ and {axis}-"
            raise CalibError(
                f"the default fit of {axis} fits {fitted}, not {axis}{direction} "
                f"({'signed' if choice.signed else 'split'}: {choice.why}); their "
                "diagnose folders have the diagnosis"
            )
        dset = next((d for d in found if d.direction == direction), None)
        if dset is None:  # says why this direction has no dataset
            (dset,) = frame_datasets(frames, axis, config.fit, (direction,))[:1]
        check_dataset(dset, config.diagnose)
    except CalibError as exc:
        with output_dir(out, "diagnose", [synced], DIAGNOSE_OUTPUTS) as tmp:
            write_json(
                tmp / "skipped.json", {"axis": axis, "direction": direction, "reason": str(exc)}
            )
        return f"skipped: {exc}"
    fit_json = out.parent.parent / "fit" / axis / "fit.json"  # the run's fit of this axis
    rec = diagnose_dataset(
        dset, axis, "auto", out, config, sources=[synced], show_progress=False,
        fit_json=fit_json if fit_json.is_file() else None,
    )  # fmt: skip
    changes = [c["text"] for c in rec.get("fit_replaced", [])]
    return f"ran; {'; '.join(changes)}" if changes else None


def compensation_target(session: Path, target: str) -> Path:
    """The ``[compensate] target`` file: absolute, or relative to the session folder,
    else to the current folder; CalibError when it is in neither."""
    p = Path(target)
    for cand in [p] if p.is_absolute() else [session / p, p]:
        if cand.is_file():
            return cand
    raise CalibError(
        f"[compensate] target {target}: file not found in {session} or the current folder; "
        "give a target CSV (time_s, <axis>_deg; docs/compensate.md)"
    )


def compensate_run(run_dir: Path, target: Path, out_dir: Path, config: PipelineConfig) -> None:
    """Feedforward commands for the target from this run's fits (docs/compensate.md).

    Datasets: ``[compensate] datasets``, else per axis of the target the direction of
    its median angle (``+`` when >= 0).
    """
    cc = config.compensate
    datasets = list(cc.datasets)
    axes = [d[:-1] for d in datasets]
    if not datasets:  # every axis of the target; compensate chooses the dataset
        head = read_csv_header(
            target, "[compensate] target file not found (a CSV with time_s and <axis>_deg)"
        )
        axes = [axis for axis in AXES if f"{axis}_deg" in head]
    fits = [run_dir / "fit" / a / "fit.json" for a in axes]
    missing = [str(f) for f in fits if not f.is_file()]
    if missing:
        raise CalibError(
            f"[compensate]: no fit for {', '.join(missing)} (the axis did not move in this "
            "session); remove that axis from the target or from [compensate] datasets"
        )
    compensate_files(
        fits,
        datasets or None,
        target,
        out_dir / "commands.csv",
        config=config,
        model=cc.model or None,
        max_counts_per_s=cc.max_counts_per_s or None,
        time_unit_s=cc.time_unit_s,
        conditioning=cc.conditioning,
    )

    write_bytes(out_dir / "target.csv", target.read_bytes())  # the target as used, for the report


def run_one_session(
    session: Path, run_dir: Path, config: PipelineConfig, force: bool
) -> list[tuple[str, str]]:
    """Run every stage of one session in order; returns (stage, outcome) pairs.

    A CalibError names the session folder, so a batch run says which one failed.
    """
    existed = run_dir.exists()
    try:
        note = claim_run_dir(session, run_dir)
        if note:
            Console(stderr=True).print(
                f"note: {note}", markup=False, highlight=False, soft_wrap=True
            )
        return [(st.name, run_stage(st, force)) for st in session_stages(session, run_dir, config)]
    except CalibError as exc:
        raise CalibError(f"session {session}: {exc}") from None
    finally:
        if not existed:
            remove_if_unused(run_dir)


def remove_if_unused(run_dir: Path) -> None:
    """Remove a run folder made by this run that holds nothing but its owner record
    (the session failed before any stage finished): no empty folder is left behind."""
    try:
        if [p.name for p in run_dir.iterdir()] == [OWNER]:
            (run_dir / OWNER).unlink()
            run_dir.rmdir()
    except OSError:
        pass


def check_run_dir(session: Path, run_dir: Path) -> None:
    """Before any work: ``run_dir`` may hold this session's run (io/outputs.py rules).

    It must not be or contain the session folder nor any file the session names, and it
    must be new, empty or a run folder (``.session.json``); whose session it is, is
    checked by :func:`claim_run_dir`.
    """
    check_not_input(run_dir, [session], what="--out")
    check_out_path(run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise CalibError(f"--out: {run_dir} is a file; give a folder for the run outputs")
    for parent in run_dir.parents:
        if parent.exists() and not parent.is_dir():
            raise CalibError(f"--out: {parent} is a file, not a folder; give a folder path")
    if run_dir.is_dir() and not (run_dir / OWNER).is_file():
        foreign = sorted(p.name for p in run_dir.iterdir())
        if foreign:
            raise CalibError(
                f"--out: {run_dir} exists and is not a run folder (it holds "
                f"{', '.join(foreign[:3])}); give another --out (nothing was changed)"
            )


OWNER = ".session.json"


def session_record(session: Path) -> dict[str, Any]:
    """What a run folder's ``.session.json`` records of its session.

    ``settings`` (:func:`session_settings`) and, per file the pipeline reads
    (:func:`stage_input_files`, named relative to the session folder), its ``stage``,
    ``size`` and ``sha256``; ``identity`` is the SHA-256 of the settings and the files'
    names, sizes and contents (SHA-256): the same for the session moved to another
    folder, different for another recording even with the same names and sizes.
    Comments, ``notes`` and files session.toml does not name are in none of them.
    """
    spec = load_session(session)
    files: dict[str, dict[str, Any]] = {}
    for stage, paths in stage_input_files(session, spec).items():
        for p in paths:
            try:
                key = p.relative_to(session).as_posix()
            except ValueError:  # an absolute path in session.toml
                key = str(p)
            files[key] = {"stage": stage, "size": p.stat().st_size, "sha256": cached_sha256(p)}
    settings = session_settings(spec)
    contents = {k: [v["size"], v["sha256"]] for k, v in files.items()}
    body = json.dumps({"settings": settings, "files": contents}, sort_keys=True, default=str)
    return {
        "identity": hashlib.sha256(body.encode()).hexdigest(),
        "session": str(session.resolve()),
        "settings": json.loads(json.dumps(settings, default=str)),
        "files": files,
    }


def input_changes(old: dict[str, Any], new: dict[str, Any]) -> tuple[list[str], str]:
    """What changed between two :func:`session_record` s: the inputs (file names,
    ``session.toml [table]``) and the first stage that reads one (``""``: none)."""
    changed: dict[str, str] = {}
    before, after = old.get("files", {}), new["files"]
    for name in sorted(set(before) | set(after)):
        a, b = before.get(name), after.get(name)
        if (a or {}).get("sha256") != (b or {}).get("sha256"):
            changed[name] = (b or a)["stage"]
    for stage, tables in new["settings"].items():
        was = old.get("settings", {}).get(stage, {})
        for key, value in tables.items():
            parts = value if key == "cameras" else {None: value}
            prev = was.get(key, {}) if key == "cameras" else {None: was.get(key)}
            for sub in sorted(set(parts) | set(prev), key=str):
                if parts.get(sub) != prev.get(sub):
                    changed[f"session.toml [{key}{'' if sub is None else '.' + sub}]"] = stage
    first = "track" if "track" in changed.values() else ("sync" if changed else "")
    return list(changed), first


def claim_run_dir(session: Path, run_dir: Path) -> str | None:
    """Record which session ``run_dir`` belongs to; refuse one made from another session.

    ``run_dir/.session.json`` holds the session's record (:func:`session_record`), first
    written with exclusive creation (two runs at once cannot both claim it). The same
    session folder with changed inputs, or the same recording moved to another folder
    (the same ``identity`` in its record: same settings, file names and contents),
    keeps its run folder: the record is updated and the stages whose inputs changed
    re-run (their stamps). Another folder with other inputs is refused, also when
    its files have the same names and sizes.

    Returns
    -------
    str or None
        A one-line note for the console: which inputs changed and which stages re-run,
        or where the moved session was; None when nothing changed.
    """
    record = session_record(session)
    marker = run_dir / OWNER
    run_dir.mkdir(parents=True, exist_ok=True)
    try:
        fd = os.open(marker, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        try:
            owner = json.loads(marker.read_text())
        except (OSError, json.JSONDecodeError):
            owner = {}
        owner = owner if isinstance(owner, dict) else {}
        moved = owner.get("session") != record["session"]
        if moved and owner.get("identity") != record["identity"]:
            raise CalibError(
                f"{run_dir} holds the results of another session ({owner.get('session', '?')}) "
                "with the same name; give this one a unique name in session.toml or use another --out"
            ) from None
        if owner != record:
            write_json(marker, record)
        return change_note(run_dir, owner, record, moved)
    except OSError as exc:
        raise CalibError(
            f"{run_dir}: cannot write there ({exc.strerror}); choose another --out"
        ) from None
    with os.fdopen(fd, "w") as f:
        json.dump(record, f)
    return None


def change_note(
    run_dir: Path, owner: dict[str, Any], record: dict[str, Any], moved: bool
) -> str | None:
    """The console note of :func:`claim_run_dir` (None: same folder, same inputs)."""
    parts = [f"session moved from {owner.get('session', '?')}"] if moved else []
    changed, first = input_changes(owner, record) if "files" in owner else ([], "")
    if changed:  # (a record without files was written by an older version: stamps decide)
        more = f" and {len(changed) - 4} more" if len(changed) > 4 else ""
        stages = (
            "track, sync and the stages after them re-run"
            if first == "track"
            else "sync and the stages after it re-run (track is up to date)"
        )
        parts.append(f"{', '.join(changed[:4])}{more} changed since its last run: {stages}")
    return f"{run_dir}: {'; '.join(parts)}" if parts else None


def checked_session_name(session: Path) -> str:
    """The session's name from session.toml, after checking every file it names exists.

    Checking up front means a session missing its encoder log fails before the
    (long) tracking stage rather than after it.
    """
    spec = load_session(session)
    check_cameras(session, spec)
    for cam_name, cam in spec.cameras.items():
        session_file(session, cam.video, f"video of camera '{cam_name}'")
        session_file(session, cam.timestamps, f"timestamps of camera '{cam_name}'")
    encoder_log_path(session, spec.encoder)
    return spec.name or session.name


def run_sessions(
    sessions: Sequence[Path],
    out: Path,
    config: PipelineConfig,
    force: bool = False,
    jobs: int = 0,
) -> dict[str, list[tuple[str, str]]]:
    """Run the pipeline on every session, in parallel processes; print a summary.

    Parameters
    ----------
    sessions : sequence of Path
        Session folders (docs/session.md).
    out : Path
        Run outputs go to ``out/<session name>/``.
    force : bool
        Redo every stage even when its stamp says it is up to date.
    jobs : int
        Parallel sessions; 0 = number of cores.
    """
    console = Console(stderr=True)
    names = _session_names(sessions)
    run_dirs = {name: Path(out) / name for name in names}
    for s, name in zip(sessions, names, strict=True):
        try:
            check_run_dir(Path(s), run_dirs[name])
        except CalibError as exc:
            raise CalibError(f"session {s}: {exc}") from None
    jobs = jobs or os.cpu_count() or 1
    work = [(Path(s), run_dirs[name], name) for s, name in zip(sessions, names, strict=True)]
    results, failed = _run_all(work, config, force, jobs, console)
    for name in names:
        if name in results:
            done = ", ".join(f"{stage}: {outcome}" for stage, outcome in results[name])
            console.print(
                f"[green]{name}[/] -> {run_dirs[name] / 'report' / 'report.html'} ({done})"
            )
    if failed:
        first = next(iter(failed.values()))
        more = (
            f" (and {len(failed) - 1} more session(s) failed, see above)" if len(failed) > 1 else ""
        )
        for exc in list(failed.values())[1:]:
            console.print(f"error: {exc}", markup=False, highlight=False)
        raise CalibError(f"{first}{more}")
    return results


def _session_names(sessions: Sequence[Path]) -> list[str]:
    """Each session's run-folder name (:func:`checked_session_name`); one line when a
    session is unusable or two share a name."""
    names = []
    for s in sessions:
        try:
            names.append(checked_session_name(Path(s)))
        except CalibError as exc:
            raise CalibError(f"session {s}: {exc}") from None
    if len(set(names)) != len(names):
        raise CalibError(
            f"two sessions share a name ({', '.join(names)}); give each a unique [name] in session.toml"
        )
    return names


def _run_all(work: list, config: PipelineConfig, force: bool, jobs: int, console) -> tuple:
    """(name -> stage outcomes, name -> CalibError) of every ``(session, run_dir, name)``
    in ``work``: one after the other with one job or one session, else in ``jobs``
    spawned processes."""
    results: dict[str, list[tuple[str, str]]] = {}
    failed: dict[str, CalibError] = {}
    if jobs == 1 or len(work) == 1:
        for session, run_dir, name in work:
            console.print(f"[bold]{name}[/]: {session}")
            try:
                results[name] = run_one_session(session, run_dir, config, force)
            except CalibError as exc:
                failed[name] = exc
        return results, failed
    # spawn, not fork: a forked child inherits OpenCV/numba thread pools and can deadlock
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=min(jobs, len(work)), mp_context=ctx) as pool:
        futures = {
            pool.submit(run_one_session, session, run_dir, config, force): name
            for session, run_dir, name in work
        }
        for fut in as_completed(futures):
            try:
                results[futures[fut]] = fut.result()
            except CalibError as exc:
                failed[futures[fut]] = exc
    return results, failed
