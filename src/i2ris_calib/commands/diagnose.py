"""``i2ris-calib diagnose``: read a synced CSV, run the diagnosis, write its outputs.

Outputs in ``OUT`` (written in a temporary folder renamed when complete; formats
in docs/diagnosis.md): ``diagnosis.json``, ``final_model.json``, ``diagnosis.md``
and one residual figure per model (``residual_00_start.png``,
``residual_01_<effect>.png``, ...).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from rich.console import Console
from rich.progress import Progress

from i2ris_calib.commands.fit import LowerCost, rerun_fit, stored_fit_record, stored_model
from i2ris_calib.config import PipelineConfig
from i2ris_calib.data.dataset import Dataset
from i2ris_calib.diagnosis.blas import single_threaded_blas
from i2ris_calib.diagnosis.cycles import loading_mask
from i2ris_calib.diagnosis.data import check_dataset
from i2ris_calib.diagnosis.report import diagnosis_markdown, diagnosis_record, paths_record
from i2ris_calib.diagnosis.workflow import diagnose_from_starts
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.fit import lower_optimum
from i2ris_calib.fitting.pipeline import dataset_cost
from i2ris_calib.hysteresis.codec import model_to_dict
from i2ris_calib.hysteresis.registry import DIAGNOSIS_STARTS, diagnosis_starts, kind_info
from i2ris_calib.io.atomic import atomic_path, write_json, write_text
from i2ris_calib.io.outputs import claim_output_dir, output_dir, output_lock
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.synced import frame_datasets, frames_for_fit, read_frames
from i2ris_calib.model import Model

STARTS = ("auto", *DIAGNOSIS_STARTS)
SCHEMA = "i2ris-calib.diagnosis/1"
#: The files ``diagnose`` writes in its output folder (``skipped.json`` inside ``run``).
OUTPUTS = ("diagnosis.json", "diagnosis.md", "final_model.json", "residual_*.png", "skipped.json")


DIRECTIONS = ("auto", "+", "-", "±")


def diagnosis_dataset(
    path: str | Path, axis: str, direction: str, fit_config, columns=None
) -> Dataset:
    """The one :class:`~i2ris_calib.data.Dataset` of ``axis`` to diagnose in a synced CSV.

    Read by the one reader (:func:`i2ris_calib.io.synced.load_datasets`), so ``fit``
    builds exactly the same dataset (samples, loss mask, held-out cycles) from the
    same file and ``[fit]`` settings; the file is read and validated once. ``direction``: ``"+"`` or ``"-"`` (``"±"`` when
    ``[fit] signed = true``), or ``"auto"``: the dataset(s) of the default fit's model
    choice (:func:`~i2ris_calib.commands.fit.datasets_for_fit`: the signed dataset when the
    input crosses zero or its excursions do not start at rest, else the split), the
    one with more in-direction samples (``"+"`` on a tie).
    """
    if direction not in DIRECTIONS:
        raise CalibError(f"--direction must be auto, +, - or ±, got '{direction}'")
    if direction in ("+", "-") and fit_config.signed:
        raise CalibError(
            f"--direction {direction}: [fit] signed = true makes one signed dataset per axis; "
            "use --direction auto (or set signed = false)"
        )
    frames = read_frames([path], axis, columns)
    if direction == "auto":  # the dataset(s) the default fit fits: signed or split
        found, _ = frames_for_fit(frames, axis, fit_config)
    elif direction == "±":  # the signed dataset, asked for: the input must cross zero
        signed = replace(fit_config, signed=True, split=False)
        found = frame_datasets(frames, axis, signed, ("±",))
        if not fit_config.signed:
            _check_crosses_zero(found[0], path)
    else:
        found = frame_datasets(frames, axis, fit_config, (direction,))
    return max(found, key=lambda d: d.rows["in_direction"])


def _check_crosses_zero(dset: Dataset, path) -> None:
    """CalibError when ``--direction ±`` names an input that stays on one side of its
    zero band (one direction's data: one model across zero has nothing to cross)."""
    enc = np.asarray(dset.enc, float)
    band = dset.bands.zero_band
    if (enc > band).any() and (enc < -band).any():
        return
    side = "+" if (enc > band).any() else "-"
    raise CalibError(
        f"--direction ±: enc_{dset.axis} in {path} never crosses zero (it stays in "
        f"{enc.min():g}..{enc.max():g}, direction {side} only); ± is one model across zero: "
        f"use --direction {side} (or auto), or set [fit] signed = true to force it"
    )


def check_start(start: str, dset: Dataset, path) -> None:
    """CalibError before any fit when ``start`` needs the signed input (``agpi``,
    ``maxwell_slip``, ``bouc_wen``) and ``dset`` is one motion direction's."""
    if start == "auto" or dset.direction == "±" or not kind_info(start).signed:
        return
    ok = ", ".join(("auto", *diagnosis_starts(False)))
    raise CalibError(
        f"--start {start} fits the signed input (one model across zero), but the {dset.axis} "
        f"dataset of {path} is {dset.name}, one motion direction; use --start {ok}, or "
        "--direction ± on a recording whose input crosses zero"
    )


def _figure(model: Model, data: Dataset, holdout: np.ndarray, title: str):
    """Residual figure (2x2): vs time (``holdout``, bool (n,), shaded), vs input per
    branch, vs rate, loop.

    The model runs over the whole history; residuals and the model line are drawn
    on the dataset's own samples only (NaN elsewhere, so no line crosses a gap).
    """
    signals = data.signals
    theta = np.asarray(data.theta_deg, float)
    y = model(signals)
    y_mine = np.where(data.in_direction, y, np.nan)
    res = theta - y
    t = np.asarray(signals.t_s, float)
    v = np.asarray(signals.v, float)
    rate = np.gradient(v, t)
    unit = "input"
    fig = Figure(figsize=(10, 7), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots(2, 2)
    ax[0, 0].plot(t, res, lw=0.6, color="0.2")
    ax[0, 0].fill_between(
        t,
        0,
        1,
        where=holdout,
        transform=ax[0, 0].get_xaxis_transform(),
        color="tab:orange",
        alpha=0.15,
        label="held out",
    )
    ax[0, 0].set(xlabel="time (s)", ylabel="residual (deg)", title="residual vs time")
    ax[0, 0].legend(loc="upper right", fontsize=8)
    up = loading_mask(v, data.bands.deadband)
    ax[0, 1].scatter(v[up], res[up], s=2, label="loading")
    ax[0, 1].scatter(v[~up], res[~up], s=2, label="unloading")
    ax[0, 1].set(xlabel=unit, ylabel="residual (deg)", title="residual vs input")
    ax[0, 1].legend(fontsize=8, markerscale=4)
    ax[1, 0].scatter(rate, res, s=2, color="tab:green")
    ax[1, 0].set(
        xlabel=f"{unit} rate (input unit/s)", ylabel="residual (deg)", title="residual vs rate"
    )
    ax[1, 1].plot(v, theta, ".", ms=2, color="0.5", label="measured")
    ax[1, 1].plot(v, y_mine, lw=0.8, color="tab:red", label="model")
    ax[1, 1].set(xlabel=unit, ylabel="angle (deg)", title="angle vs input")
    ax[1, 1].legend(fontsize=8)
    sign = " (angle -theta: the paper's |deg|)" if data.direction == "-" else ""
    fig.suptitle(title + sign)
    return fig


def _save(fig: Figure, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90)


def diagnose_file(
    data: Path,
    axis: str,
    start: str = "auto",
    out: Path | None = None,
    config=None,
    direction: str = "auto",
    fit_json: Path | None = None,
) -> dict:
    """Run the diagnosis on ``data`` and write ``out`` (see module doc). Returns diagnosis.json.

    ``fit_json``: the fit.json of ``fit`` on the same file and ``[fit]`` settings
    (``--fit``); when the diagnosis reaches a lower cost of a model it holds, the fit
    is rerun from it and fit.json replaced (:func:`replace_stored_fit`).

    The diagnosed dataset is :func:`diagnosis_dataset` (the one reader, ``[fit]``
    bands and held-out cycles): ``fit --model-file OUT/final_model.json`` with the
    same file and config refits the final model on exactly these samples.
    ``start``: ``"gpi"``, ``"egpi"`` or ``"auto"`` (both, reconciled by
    :func:`~i2ris_calib.diagnosis.workflow.diagnose_from_starts`; both paths in
    diagnosis.json ``paths``).
    """
    if start not in STARTS:
        raise CalibError(f"--start must be one of {', '.join(STARTS)}, got '{start}'")
    cfg = config or PipelineConfig()
    claim_output_dir(Path(out) if out is not None else Path("diagnose_out"), "diagnose",
                     [Path(data)], OUTPUTS)  # fmt: skip
    dset = diagnosis_dataset(Path(data), axis, direction, cfg.fit, cfg.columns)
    check_start(start, dset, data)
    check_dataset(dset, cfg.diagnose)
    return diagnose_dataset(dset, axis, start, out, cfg, sources=[Path(data)], fit_json=fit_json)


def diagnose_dataset(
    dset: Dataset,
    axis: str,
    start: str,
    out: Path | None,
    cfg,
    sources: list[Path],
    show_progress: bool = True,
    fit_json: Path | None = None,
) -> dict:
    """Diagnose one dataset and write ``out`` (see module doc); returns diagnosis.json.

    Used by ``diagnose`` (one file) and by ``run`` (``[run] diagnose = true``, every
    axis and direction of the session; ``fit_json``: the run's fit of the axis).
    ``fit_json``: see :func:`diagnose_file`; diagnosis.json's ``fit_replaced`` lists
    what was replaced, and a note says it.
    """
    out = claim_output_dir(
        Path(out) if out is not None else Path("diagnose_out"), "diagnose", sources, OUTPUTS
    )
    stored = stored_fit_record(fit_json, dset, cfg) if fit_json is not None else None
    with output_lock(out, command="diagnose"):  # one diagnose at a time into ``out``
        auto = _diagnosed(dset, start, cfg, show_progress)
        diag = auto.diagnosis
        models = [diag.start_model] + [s.model_after for s in diag.steps]
        labels = ["start"] + [s.effect for s in diag.steps]
        figures = [f"residual_{i:02d}_{lab}.png" for i, lab in enumerate(labels)]
        record = diagnosis_record(diag, figures, auto=auto)
        record.update(_dataset_fields(dset, axis, start, auto, sources, cfg))
        if stored is not None:
            changes = replace_stored_fit(Path(fit_json), stored, dset, auto, cfg)
            record["fit_replaced"] = changes
            record["notes"] = [*record.get("notes", []), *(c["text"] for c in changes)]
        with output_dir(out, "diagnose", sources, OUTPUTS) as tmp:
            for i, (m, name) in enumerate(zip(models, figures, strict=True)):
                title = f"{dset.name}: {' + '.join([auto.start, *labels[1 : i + 1]])}"
                _save(_figure(m, dset, dset.holdout, title), tmp / name)
            write_json(tmp / "diagnosis.json", record)
            final = model_to_dict(diag.final_model)
            final.update(
                axis=axis, dataset=dset.name, direction=dset.direction, abs_input=dset.abs_fitted
            )
            write_json(tmp / "final_model.json", final)
            write_text(tmp / "diagnosis.md", diagnosis_markdown(record))
        return record


def lower_costs(stored: tuple[dict, dict], path: Path, dset: Dataset, auto, cfg) -> list:
    """The :class:`~i2ris_calib.commands.fit.LowerCost` of each model the fit.json
    ``stored`` = (document, ``dset``'s record, read from ``path``) holds and a path of
    the diagnosis ``auto`` started from: the lowest of the diagnosis's refits of it
    (:attr:`~i2ris_calib.diagnosis.results.Diagnosis.base_refits`) by the fit's own
    cost on the whole dataset (run after the stored fit's start state), when it is
    lower than the stored fit's (:func:`~i2ris_calib.fitting.fit.lower_optimum`)."""
    doc, record = stored
    out = []
    for kind, diag in auto.paths.items():
        if kind not in record["models"] or not diag.base_refits:
            continue
        model, state = stored_model(doc, record, kind, path)
        before = dataset_cost(model, dset, cfg.fit, state)
        costs = [(dataset_cost(r.model, dset, cfg.fit, state), r) for r in diag.base_refits]
        cost, best = min(costs, key=lambda c: c[0])
        if lower_optimum(before, cost):
            params = {p.name: float(p.value) for p in best.model.parameters}
            out.append(LowerCost(dset.name, kind, params, cost, before, f"diagnose's {best.how}"))
    return out


def replace_stored_fit(path: Path, stored, dset: Dataset, auto, cfg) -> list[dict]:
    """Rerun the fit of ``path`` from the lower costs the diagnosis found
    (:func:`lower_costs`; the fit's own code: :func:`~i2ris_calib.commands.fit.rerun_fit`),
    replacing fit.json and predictions.csv; returns the changes (empty: none found, and
    fit.json is not touched)."""
    with single_threaded_blas():
        lower = lower_costs(stored, path, dset, auto, cfg)
        return rerun_fit(path, lower, cfg, stage="diagnose") if lower else []


def _diagnosed(dset: Dataset, start: str, cfg, show_progress: bool):
    """:func:`diagnose_from_starts` on ``dset`` (``start`` ``auto``: the model fit picks
    on the signed input) behind a progress line."""
    starts = None if start == "auto" else (start,)
    console = Console(stderr=True)  # off a terminal: no bar, so no blank line either
    shown = show_progress and console.is_terminal
    with (
        Progress(console=console, transient=True, disable=not shown) as bar,
        single_threaded_blas(),
    ):
        task = bar.add_task(f"diagnose {dset.name}", total=None)
        return diagnose_from_starts(
            dset,
            cfg.diagnose,
            cfg.fit,
            starts=starts,
            progress=lambda name: bar.update(task, description=f"diagnose {dset.name}: {name}"),
        )


def _dataset_fields(dset: Dataset, axis: str, start: str, auto, sources: list[Path], cfg) -> dict:
    """diagnosis.json's fields on the dataset, the starts and the provenance."""
    return dict(
        schema=SCHEMA,
        axis=axis,
        start=start,
        start_model=auto.start,
        reconciliation=auto.sentence,
        paths=paths_record(auto),
        source=", ".join(str(p) for p in sources),
        dataset=dset.name,
        direction=dset.direction,
        abs_input=dset.abs_fitted,
        n_samples=dset.n_samples,
        rows=dict(dset.rows),
        bands={
            "zero_band": dset.bands.zero_band,
            "deadband": dset.bands.deadband,
            "input_noise": dset.bands.noise,
            "derived": list(dset.bands.derived),
        },
        provenance=provenance(sources, cfg),
    )
