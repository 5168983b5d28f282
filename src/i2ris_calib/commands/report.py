"""``i2ris-calib report RUN_DIR``: read a run folder, write report.html + report.md.

The run folder is read by :func:`i2ris_calib.io.run_folder.load_run`. The output
folder is written as a whole (temporary folder, renamed when complete).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import Progress

from i2ris_calib import __version__
from i2ris_calib.errors import CalibError
from i2ris_calib.io.config_io import load_config
from i2ris_calib.io.outputs import claim_output_dir, output_dir, output_lock
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.run_folder import FIT_FILES, is_fit_folder, load_run
from i2ris_calib.report.build import build_document, section_count
from i2ris_calib.report.data import RunData
from i2ris_calib.report.render import render_html, render_markdown

REPORT_FILES = ("report.html", "report.md", "figures")
#: The parts of a run folder a report reads; its --out must not be or contain one.
RUN_PARTS = ("track", "sync", "fit", "diagnose", "compensate")
FIGURE_DIR = "figures"


def report_provenance(root: Path, inputs: list[Path], config: Any) -> dict[str, Any]:
    """Provenance block of the report, input paths relative to the run folder."""
    prov = provenance(inputs, config)
    base = root.resolve()
    prov["inputs"] = {
        Path(p).resolve().relative_to(base).as_posix(): h
        for p, h in zip(inputs, prov["inputs"].values(), strict=True)
    }
    return prov


def _build_with_progress(run: RunData, report_config: Any, prov: dict[str, Any]):
    """build_document with a transient rich progress bar on stderr (one step per section)."""
    console = Console(stderr=True)  # off a terminal: no bar, so no blank line either
    with Progress(console=console, transient=True, disable=not console.is_terminal) as bar:
        task = bar.add_task("report", total=section_count(run))
        started = []

        def step(label: str) -> None:
            if started:
                bar.advance(task)
            started.append(label)
            bar.update(task, description=f"report: {label}")

        doc = build_document(run, report_config, prov, progress=step)
        bar.advance(task)
    return doc


def _template(name: str) -> str:
    return (
        resources.files("i2ris_calib.report")
        .joinpath("templates", name)
        .read_text(encoding="utf-8")
    )


def _inputs(root: Path) -> list[Path]:
    """What a report of ``root`` reads: the run parts, or a fit folder's files."""
    return [root / d for d in (FIT_FILES if is_fit_folder(root) else RUN_PARTS)]


def _check_out(out: Path, root: Path) -> None:
    """Refuse an output folder that is or contains the run (or fit) folder, or holds
    anything but a previous report (io/outputs.py)."""
    o, r = out.resolve(), root.resolve()
    if o == r or o in r.parents:
        what = "fit folder" if is_fit_folder(root) else "run folder"
        raise CalibError(f"--out {out} contains the {what} {root}; choose e.g. {root / 'report'}")
    claim_output_dir(out, "report", _inputs(root), REPORT_FILES)


def write_report(run_dir: str | Path, out: str | Path | None = None, config: Any = None) -> Path:
    """Write ``report.html``, ``report.md`` and ``figures/*.png`` for a run folder.

    Parameters
    ----------
    run_dir : path
        The run folder, or a ``fit`` output folder (the report then holds the model
        sections alone).
    out : path, optional
        Output folder (default ``RUN_DIR/report``, ``FIT_DIR/report``); replaced as a whole.
    config : PipelineConfig, optional
        Its ``report`` section sets figure DPI and sizes; recorded in provenance.

    Returns
    -------
    Path
        The written ``report.html``.
    """
    root = Path(run_dir)
    cfg = config if config is not None else load_config(None)
    out_dir = Path(out) if out is not None else root / "report"
    if not root.is_dir():  # before the lock below makes parent folders for itself
        raise CalibError(f"run folder not found: {root} (give the folder written by 'run')")
    _check_out(out_dir, root)
    with output_lock(out_dir, command="report"):  # one report at a time into ``out``
        run, inputs = load_run(root)
        prov = report_provenance(root, inputs, cfg)
        doc = _build_with_progress(run, cfg.report, prov)
        page = render_html(doc, _template("report.html"), _template("report.css"), __version__)
        markdown, files = render_markdown(doc, FIGURE_DIR)
        with output_dir(out_dir, "report", _inputs(root), REPORT_FILES) as tmp:
            tmp.chmod(0o755)  # mkdtemp makes it private; a report is meant to be shared
            (tmp / "report.html").write_text(page, encoding="utf-8")
            (tmp / "report.md").write_text(markdown, encoding="utf-8")
            (tmp / FIGURE_DIR).mkdir()
            for rel, png in files.items():
                (tmp / rel).write_bytes(png)
        return out_dir / "report.html"
