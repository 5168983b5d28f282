"""Command-line interface: thin wrappers that parse options, load config, call one function.

Heavy imports (cv2, numba, matplotlib) happen inside the commands, so ``--help`` is
fast. Every user-fixable problem is a :class:`~i2ris_calib.errors.CalibError`,
printed as one line with exit status 2; ``--debug`` shows the traceback first (the
status stays 2). Help is plain text (no Rich markup): flags without value
placeholders, ``SESSION...``/``[OUT]`` usage lines (:class:`_Command`).
"""

from __future__ import annotations

import os
import sys
import traceback
from pathlib import Path

import typer
from typer.core import TyperArgument, TyperCommand, TyperOption

from i2ris_calib import __version__
from i2ris_calib.hysteresis import kinds as _kinds
from i2ris_calib.interrupts import sigint_guard

# Words a user may put after a flag as if it took a value (`run S --force true`).
_BOOL_WORDS = frozenset({"true", "false", "yes", "no", "on", "off", "1", "0"})
# Value placeholders for options declared without metavar= (click's own names).
_TYPE_METAVARS = {"int": "INTEGER", "float": "FLOAT", "str": "TEXT", "Path": "PATH"}

# The model kinds the options accept, from the names table of the registry
# (i2ris_calib.hysteresis.kinds: no model imported, so --help stays fast).
#: Kinds of a motion-direction dataset (registry ``MODEL_KINDS``).
_DIRECTION_KINDS = _kinds.MODEL_KINDS
#: Kinds that need the whole signed input of an axis (registry rows with ``signed``).
_SIGNED_ONLY_KINDS = _kinds.SIGNED_ONLY_KINDS
#: ``fit --model`` (registry ``BUILT_KINDS``; or ``all``).
_FIT_MODELS = _kinds.BUILT_KINDS
#: ``compensate --model`` (registry ``INVERSE_KINDS``; or ``diagnosed``).
_INVERSE_MODELS = _kinds.INVERSE_KINDS
#: ``diagnose --start`` (registry ``DIAGNOSIS_STARTS``; or ``auto``).
_DIAGNOSIS_STARTS = _kinds.DIAGNOSIS_STARTS


def _one_of(names: tuple[str, ...]) -> str:
    """``"a, b or c"``."""
    return f"{', '.join(names[:-1])} or {names[-1]}" if len(names) > 1 else names[0]


class _Command(TyperCommand):
    """Help in the usual notation: ``SESSION...`` for a required argument, ``[OUT]``
    for an optional one, ``--out PATH`` for an option, a flag without a value; and a
    usage error for a boolean word after a flag (``--force true``), which would
    otherwise be read as the next argument."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        for param in self.params:
            if isinstance(param, TyperOption) and param.metavar is None and not param.is_flag:
                bare = param.bare_type().removeprefix("list[").removesuffix("]")
                param.metavar = _TYPE_METAVARS.get(bare, bare.upper())
            elif isinstance(param, TyperArgument) and param.metavar is None:
                param.metavar = param.name.upper()

    def collect_usage_pieces(self, ctx: typer.Context) -> list[str]:
        pieces = [self.options_metavar] if self.options_metavar else []
        for param in self.get_params(ctx):
            if isinstance(param, TyperArgument):
                pieces.append(_argument_label(param))
            else:
                pieces.extend(param.get_usage_pieces(ctx))
        return pieces

    def format_options(self, ctx: typer.Context, formatter) -> None:
        args, opts = [], []
        for param in self.get_params(ctx):
            record = param.get_help_record(ctx)
            if record is None:
                continue
            if isinstance(param, TyperArgument):  # the label alone, no "<list[Path]>"
                args.append((_argument_label(param).strip("[]"), record[1]))
            else:
                opts.append(record)
        for title, rows in (("Arguments", args), ("Options", opts)):
            if rows:
                with formatter.section(title):
                    formatter.write_dl(rows)

    def parse_args(self, ctx: typer.Context, args: list[str]) -> list[str]:
        flags = {
            name
            for p in self.params
            if isinstance(p, TyperOption) and p.is_flag
            for name in (*p.opts, *p.secondary_opts)
        }
        for flag, word in zip(args, args[1:], strict=False):
            if flag in flags and word.lower() in _BOOL_WORDS and not Path(word).exists():
                raise typer.BadParameter(
                    f"'{word}' after {flag}: {flag} is a flag and takes no value (write "
                    f"{flag} alone)",
                    ctx=ctx,
                )
        return super().parse_args(ctx, args)


def _argument_label(param: TyperArgument) -> str:
    """``SESSION...`` (required, several), ``[OUT]`` (optional)."""
    label = param.metavar + ("..." if param.nargs != 1 else "")
    return label if param.required else f"[{label}]"


class _Typer(typer.Typer):
    """Every command of the app uses :class:`_Command`."""

    def command(self, *args, cls=None, **kwargs):
        return super().command(*args, cls=cls or _Command, **kwargs)


app = _Typer(
    name="i2ris-calib",
    help="Calibrate the I2RIS snake robot: track markers, sync clocks, fit GPI/EGPI hysteresis, report.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain help: "[simulate]" stays text, no "<bool>" after flags
)

ConfigOpt = typer.Option(
    None,
    "--config",
    "-c",
    metavar="PIPELINE.toml",
    help="Pipeline TOML (docs/config.md); defaults if omitted.",
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"i2ris-calib {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    debug: bool = typer.Option(False, "--debug", help="Show Python tracebacks on errors."),
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version."
    ),
) -> None:
    """I2RIS calibration pipeline."""


def _config(path: Path | None):
    from i2ris_calib.io.config_io import load_config

    return load_config(path)


@app.command(short_help="Render a synthetic two-microscope session (known truth).")
def simulate(
    out: Path = typer.Option(
        ..., "--out", "-o", metavar="SESSION", help="Session folder to create."
    ),
    config: Path | None = ConfigOpt,
    seed: int | None = typer.Option(
        None, metavar="N", help="Random seed (overrides [simulate] seed)."
    ),
    force: bool = typer.Option(
        False, "--force", help="Replace a folder simulate wrote (never a recording)."
    ),
) -> None:
    """Render a synthetic two-microscope session with known ground truth."""
    cfg = _config(config)
    from i2ris_calib.commands.simulate import write_simulated_session

    folder = write_simulated_session(out, cfg, seed=seed, force=force)
    typer.echo(f"wrote {folder} (videos, timestamps, encoders.csv, session.toml; truth in truth/)")


@app.command(short_help="Track the cube in both videos: pitch and yaw per frame.")
def track(
    session: Path = typer.Argument(
        ..., metavar="SESSION", help="Session folder (docs/session.md)."
    ),
    out: Path | None = typer.Option(
        None, "--out", "-o", metavar="DIR", help="Output folder (default SESSION/track)."
    ),
    config: Path | None = ConfigOpt,
) -> None:
    """Track the ArUco cube in both videos: pitch and yaw per frame with a quality flag."""
    cfg = _config(config)
    from i2ris_calib.commands.track import track_session

    track_session(session, out, cfg)


@app.command(short_help="Camera intrinsics from ChArUco views or a ROS YAML.")
def calibrate(
    inputs: list[Path] = typer.Argument(
        ..., metavar="INPUTS", help="ChArUco images/videos, or one ROS camera_info YAML."
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", metavar="CAMERA.yaml", help="Camera YAML to write (OpenCV FileStorage)."
    ),
    config: Path | None = ConfigOpt,
) -> None:
    """Camera intrinsics from ChArUco board views (or convert a ROS camera_info YAML)."""
    cfg = _config(config)
    from i2ris_calib.commands.calibrate import calibrate_camera_files

    calibrate_camera_files(inputs, out, cfg)


@app.command(short_help="Camera -> encoder clock (offset, drift); the synced CSV.")
def sync(
    session: Path = typer.Argument(..., metavar="SESSION", help="Session folder."),
    angles: Path | None = typer.Option(
        None, metavar="ANGLES.csv", help="Tracked angles CSV (default SESSION/track/angles.csv)."
    ),
    out: Path | None = typer.Option(
        None, "--out", "-o", metavar="DIR", help="Output folder (default SESSION/sync)."
    ),
    config: Path | None = ConfigOpt,
    method: str | None = typer.Option(
        None,
        "--method",
        metavar="METHOD",
        help="auto, event, model or xcorr (overrides sync.method of the config).",
    ),
) -> None:
    """Estimate camera/encoder clock offset and drift; write the synced CSV."""
    cfg = _config(config)
    from i2ris_calib.commands.sync import sync_session, with_method

    sync_session(session, angles, out, with_method(cfg, method))


@app.command(short_help="Fit hysteresis models (GPI, EGPI, two-tendon GPI).")
def fit(
    data: list[Path] = typer.Argument(
        ..., metavar="DATA.csv", help="Synced CSV file(s) (docs/formats.md)."
    ),
    axis: str = typer.Option(..., "--axis", metavar="AXIS", help="yaw or pitch."),
    model: str = typer.Option(
        "all",
        "--model",
        metavar="MODEL",
        help=f"{_one_of((*_FIT_MODELS, 'all'))} ({', '.join(_SIGNED_ONLY_KINDS)}: signed input).",
    ),
    out: Path = typer.Option(Path("fit_out"), "--out", "-o", metavar="DIR", help="Output folder."),
    config: Path | None = ConfigOpt,
    model_file: Path | None = typer.Option(
        None,
        "--model-file",
        metavar="FINAL_MODEL.json",
        help="Also refit a final_model.json written by 'diagnose'.",
    ),
    signed: bool = typer.Option(
        False, "--signed", help="One model on the whole signed input (loops that cross zero)."
    ),
    split: bool = typer.Option(
        False, "--split", help="The paper's split into motion directions, whatever the input."
    ),
    columns: str | None = typer.Option(
        None,
        "--columns",
        metavar="COLUMNS",
        help='Your file\'s columns and units: "time_s=Img TS,yaw_deg=yaws,...".',
    ),
) -> None:
    """Fit hysteresis models (Levenberg-Marquardt): the paper's GPI/EGPI per motion
    direction, or a two-tendon GPI over the signed input when the input crosses zero."""
    cfg = _config(config)
    if signed or split:
        from dataclasses import replace

        cfg = replace(cfg, fit=replace(cfg.fit, signed=signed, split=split))
    from i2ris_calib.commands.fit import fit_files
    from i2ris_calib.io.synced import with_columns

    cfg = with_columns(cfg, columns)
    fit_files(data, axis=axis, model=model, out=out, config=cfg, model_file=model_file)
    typer.echo(f"wrote {out / 'fit.json'} and predictions.csv")


@app.command(short_help="Feedforward motor commands for a target tip angle.")
def compensate(
    fit_json: list[Path] = typer.Argument(
        ..., metavar="FIT.json", help="fit.json file(s) from 'fit' (one per axis)."
    ),
    dataset: list[str] | None = typer.Option(
        None,
        "--dataset",
        metavar="DATASET",
        help="yaw+, yaw-, yaw±, pitch+, pitch- or pitch± (one per axis); omit to let compensate choose from the target.",
    ),
    target: Path = typer.Option(
        ..., "--target", metavar="TARGET.csv", help="Target CSV: time_s, yaw_deg and/or pitch_deg."
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", metavar="COMMANDS.csv", help="Commands to write (+ compensate.json)."
    ),
    model: str | None = typer.Option(
        None,
        "--model",
        metavar="MODEL",
        help=f"{_one_of((*_INVERSE_MODELS, _kinds.DIAGNOSED))} (default: fit.json's recommended model).",
    ),
    max_counts_per_s: float | None = typer.Option(
        None, "--max-counts-per-s", metavar="RATE", help="Motor rate limit (counts/s)."
    ),
    start_counts: float | None = typer.Option(
        None,
        "--start-counts",
        metavar="COUNTS",
        help="Encoder counts before the first sample (e.g. 0 at rest).",
    ),
    model_file: Path | None = typer.Option(
        None,
        "--model-file",
        metavar="FINAL_MODEL.json",
        help="final_model.json (structure of --model diagnosed).",
    ),
    time_unit_s: float | None = typer.Option(
        None,
        "--time-unit-s",
        metavar="SECONDS",
        help="Seconds per unit of the target's time_s (0.001 for ms).",
    ),
    conditioning: str | None = typer.Option(
        None,
        "--conditioning",
        metavar="auto|sweep|none",
        help="Start state: 'sweep' prepends a rate-limited sweep to both ends of the fitted "
        "range (a known state); 'auto' (default) sweeps when the fit's recording started "
        "mid-loop; 'none' starts from rest (or --history).",
    ),
    history: Path | None = typer.Option(
        None,
        "--history",
        metavar="HISTORY.csv",
        help="Commands sent before (enc_<axis> columns, oldest first, from rest; e.g. an "
        "earlier COMMANDS.csv or the encoder log): start from the state they leave.",
    ),
    config: Path | None = ConfigOpt,
) -> None:
    """Feedforward motor commands that make the fitted model follow a target angle."""
    cfg = _config(config)
    from i2ris_calib.commands.compensate import compensate_files, summary_lines

    doc = compensate_files(
        fit_json, dataset, target, out, cfg, model=model, max_counts_per_s=max_counts_per_s,
        start_counts=start_counts, model_file=model_file, time_unit_s=time_unit_s,
        conditioning=conditioning, history=history,
    )  # fmt: skip
    for line in summary_lines(doc):
        typer.echo(line)
    for rec in doc["axes"].values():
        for warning in rec.get("warnings", ()):
            typer.echo(f"warning: {warning}", err=True)
    typer.echo(f"wrote {out} and {out.with_name('compensate.json')}")


@app.command("paper-sim", short_help="Reproduce the paper's simulation (Section 3.1, Fig 3-4).")
def paper_sim(
    out: Path = typer.Option(..., "--out", "-o", metavar="DIR", help="Output folder."),
) -> None:
    """Reproduce the paper's simulation verification (Section 3.1, Fig 3c/3d/4)."""
    from i2ris_calib.commands.paper_sim import write_paper_sim

    write_paper_sim(out)
    typer.echo(f"wrote {out} (paper_sim.csv, paper_sim.json, fig3c.png, fig3d.png, fig4.png)")


@app.command(short_help="Find the missing effect where model and data disagree.")
def diagnose(
    data: Path = typer.Argument(..., metavar="DATA.csv", help="Synced CSV with both axes."),
    axis: str = typer.Option(..., "--axis", metavar="AXIS", help="yaw or pitch."),
    start: str = typer.Option(
        "auto",
        "--start",
        metavar="MODEL",
        help="Starting model: auto (on a signed input the model fit picks, agpi when the other "
        "motor moves with it; else gpi and egpi, one reconciled answer), "
        f"{_one_of(_DIAGNOSIS_STARTS)}.",
    ),
    out: Path = typer.Option(
        Path("diagnose_out"), "--out", "-o", metavar="DIR", help="Output folder."
    ),
    direction: str = typer.Option(
        "auto",
        "--direction",
        metavar="DIRECTION",
        help="+, -, ± or auto (the input fit chooses: signed through zero, else the direction "
        "with more samples).",
    ),
    config: Path | None = ConfigOpt,
    columns: str | None = typer.Option(
        None,
        "--columns",
        metavar="COLUMNS",
        help='Your file\'s columns and units: "time_s=Img TS,yaw_deg=yaws,...".',
    ),
    fit: Path | None = typer.Option(
        None,
        "--fit",
        metavar="FIT.json",
        help="fit.json of 'fit' on this file (same config): replaced when the diagnosis "
        "finds a lower cost of a model it holds (docs/diagnosis.md).",
    ),
) -> None:
    """Find where model and measurement disagree, name the missing effect, add it, refit."""
    cfg = _config(config)
    from i2ris_calib.commands.diagnose import diagnose_file
    from i2ris_calib.diagnosis.report import verdict_line
    from i2ris_calib.io.synced import with_columns

    cfg = with_columns(cfg, columns)
    rec = diagnose_file(
        data, axis=axis, start=start, out=out, config=cfg, direction=direction, fit_json=fit
    )
    typer.echo(verdict_line(rec))  # the whole verdict, paths and alternatives: diagnosis.md
    for note in rec.get("notes", []):
        if note.startswith("coupling"):  # coupling named, or not separable (issue 20)
            typer.echo(note)
    for change in rec.get("fit_replaced", []):  # a lower cost of a stored fit (issue 31)
        typer.echo(change["text"])
    typer.echo(f"wrote {out} (details in {out / 'diagnosis.md'})")


@app.command(short_help="Write the HTML report and its Markdown twin.")
def report(
    run_dir: Path = typer.Argument(
        ..., metavar="RUN_DIR", help="Run folder written by 'run' (or by track/sync/fit)."
    ),
    out: Path | None = typer.Option(
        None, "--out", "-o", metavar="DIR", help="Output folder (default RUN_DIR/report)."
    ),
    config: Path | None = ConfigOpt,
) -> None:
    """Write a self-contained HTML report and its Markdown twin (docs/report.md)."""
    cfg = _config(config)
    from i2ris_calib.commands.report import write_report

    page = write_report(run_dir, out, cfg)
    typer.echo(f"wrote {page} and {page.with_name('report.md')}")


@app.command(short_help="track -> sync -> fit -> report; up-to-date stages skipped.")
def run(
    sessions: list[Path] = typer.Argument(..., metavar="SESSION", help="Session folder(s)."),
    out: Path = typer.Option(
        Path("runs"), "--out", "-o", metavar="DIR", help="Folder for the run outputs."
    ),
    config: Path | None = ConfigOpt,
    force: bool = typer.Option(False, "--force", help="Redo every stage even if up to date."),
    jobs: int = typer.Option(
        0, "--jobs", "-j", metavar="N", help="Parallel sessions (0 = number of cores)."
    ),
) -> None:
    """track -> sync -> fit -> report for each session; stages skipped when up to date."""
    cfg = _config(config)
    from i2ris_calib.commands.run import run_sessions

    run_sessions(sessions, out=out, config=cfg, force=force, jobs=jobs)


@app.command("config", short_help="Print the effective configuration as TOML.")
def show_config(config: Path | None = ConfigOpt) -> None:
    """Print the effective configuration (defaults merged with --config) as TOML."""
    from i2ris_calib.io.config_io import to_toml

    typer.echo(to_toml(_config(config)), nl=False)


INTERRUPTED = "interrupted (no partial outputs were kept)"


def _interrupted(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt is behind ``exc`` (its cause/context chain)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def main(argv: list[str] | None = None) -> int:
    """Console entry point: one-line errors, no traceback unless --debug.

    Typer handles usage errors, ``--help`` and exit codes itself (it exits through
    SystemExit); everything else that escapes a command is caught here.
    """
    args = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in args
    if not debug:  # FFmpeg's and OpenCV's own log lines only with --debug (read at cv2 import)
        os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
        os.environ.setdefault("OPENCV_LOG_LEVEL", "SILENT")
    # Ctrl-C in compiled code (numba) or in a __del__ is raised at the next safe point
    # (i2ris_calib/interrupts.py); once the result is decided, the console command
    # ignores it so that a Ctrl-C while the interpreter shuts down cannot turn it into
    # "killed by SIGINT" without a message
    with sigint_guard(ignore_after=argv is None):
        return _run(args, debug)


def _run(args: list[str], debug: bool) -> int:
    """:func:`main` without the SIGINT guard."""
    from i2ris_calib.errors import CalibError

    try:
        app(args=args, prog_name="i2ris-calib")
    except SystemExit as exc:
        code = exc.code
        if _interrupted(exc):  # Typer turns Ctrl-C into a silent exit 130
            typer.echo(INTERRUPTED, err=True)
            return 130
        return code if isinstance(code, int) else (0 if code is None else 1)
    except KeyboardInterrupt:
        typer.echo(INTERRUPTED, err=True)
        return 130
    except CalibError as exc:
        if debug:  # the traceback, then the same line and status as without --debug
            traceback.print_exc()
        typer.echo(f"error: {exc}", err=True)
        return 2
    except Exception as exc:  # noqa: BLE001 - last line of defence, see --debug
        if debug:
            traceback.print_exc()
            return 1
        typer.echo(
            f"internal error: {type(exc).__name__}: {exc} (rerun with --debug for the traceback)",
            err=True,
        )
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
