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
import pandas as pd

from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.model import Model, Signals

AXES = ("yaw", "pitch")
STARTS = ("gpi", "egpi")
SCHEMA = "i2ris-calib.diagnosis/1"


def read_synced(
    path: Path, axis: str, direction: str = "auto", zero_band_counts: float = 5.0
) -> tuple[Signals, np.ndarray, bool]:
    """Signals and measured angle of ``axis`` from a synced CSV (docs/formats.md).

    Rows whose ``status`` is not ``measured`` keep their input but get a NaN
    angle. One motion direction is diagnosed: ``"+"`` keeps the rows with input
    above ``-zero_band_counts`` (positive excursions and rests), ``"-"`` those
    below ``+zero_band_counts`` and uses |counts| -> |deg| (the paper's
    convention), ``"auto"`` picks the direction with more samples outside the
    zero band.

    Returns
    -------
    signals : Signals
        ``v`` (counts), ``t_s`` (s), ``v_other`` and ``theta_other_deg`` of the
        other axis when present.
    theta_deg : ndarray, shape (n,)
    abs_input : bool
        True when absolute values were taken.
    """
    if axis not in AXES:
        raise CalibError(f"--axis must be yaw or pitch, got '{axis}'")
    if not Path(path).is_file():
        raise CalibError(f"synced CSV not found: {path} (run 'i2ris-calib sync' first)")
    try:
        df = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CalibError(f"cannot read {path} as CSV: {str(exc).splitlines()[0]}") from None
    other = "pitch" if axis == "yaw" else "yaw"
    need = ["time_s", f"enc_{axis}", f"{axis}_deg"]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise CalibError(
            f"{path}: missing column(s) {', '.join(missing)} (a synced CSV has time_s, "
            "enc_yaw, enc_pitch, yaw_deg, pitch_deg, status; see docs/formats.md)"
        )
    cols = {}
    for c in [*need, f"enc_{other}", f"{other}_deg"]:
        if c in df.columns:
            col = pd.to_numeric(df[c], errors="coerce")
            if c != f"{axis}_deg" and c != f"{other}_deg" and col.isna().any():
                bad = int(col.isna().idxmax())
                raise CalibError(
                    f"{path}: column {c} has a missing or non-numeric value at row {bad + 2}"
                )
            cols[c] = col.to_numpy(dtype=float)
    t = cols["time_s"]
    if t.size < 10:
        raise CalibError(
            f"{path}: only {t.size} rows; diagnosis needs a recording of several cycles"
        )
    if np.any(np.diff(t) <= 0):
        bad = int(np.argmax(np.diff(t) <= 0)) + 3
        raise CalibError(
            f"{path}: time_s must increase strictly (row {bad}); sort the file by time"
        )
    theta = cols[f"{axis}_deg"].copy()
    if "status" in df.columns:
        theta[df["status"].astype(str).to_numpy() != "measured"] = np.nan
    if np.isfinite(theta).sum() < 10:
        raise CalibError(f"{path}: fewer than 10 measured {axis} angles")
    th_other = cols.get(f"{other}_deg")
    if th_other is not None and "status" in df.columns:
        th_other = th_other.copy()
        th_other[df["status"].astype(str).to_numpy() != "measured"] = np.nan
    if th_other is not None:
        ok = np.isfinite(th_other)
        th_other = np.interp(t, t[ok], th_other[ok]) if ok.sum() >= 2 else None
    v = cols[f"enc_{axis}"]
    sign = _direction(v, direction, zero_band_counts, path)
    keep = v * sign > -zero_band_counts
    theta = np.where(keep, theta, np.nan)[keep]
    sig = Signals(v=v, t_s=t, v_other=cols.get(f"enc_{other}"), theta_other_deg=th_other)
    sig = sig.take(np.flatnonzero(keep))
    if sign < 0:
        sig = replace(sig, v=np.abs(sig.v))
        theta = np.abs(theta)
    if np.isfinite(theta).sum() < 10:
        raise CalibError(f"{path}: fewer than 10 measured {axis} angles in direction {direction}")
    return sig, theta, sign < 0


def _direction(v: np.ndarray, direction: str, zero_band: float, path) -> int:
    """+1 or -1: the motion direction to diagnose (see :func:`read_synced`)."""
    n_pos, n_neg = int((v > zero_band).sum()), int((v < -zero_band).sum())
    if direction == "auto":
        if n_pos == 0 and n_neg == 0:
            raise CalibError(f"{path}: the axis input never leaves +-{zero_band} counts")
        return 1 if n_pos >= n_neg else -1
    if direction not in ("+", "-"):
        raise CalibError(f"--direction must be auto, + or -, got '{direction}'")
    if (n_pos if direction == "+" else n_neg) < 10:
        raise CalibError(f"{path}: fewer than 10 samples in direction {direction}")
    return 1 if direction == "+" else -1


def _figure(model: Model, signals: Signals, theta: np.ndarray, holdout: np.ndarray, title: str):
    """Residual figure (2x2): vs time, vs input per branch, vs rate, loop."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from i2ris_calib.diagnosis.effects import model_values

    y = model.evaluate(signals, model_values(model))
    res = theta - y
    t = np.asarray(signals.t_s, float)
    v = np.asarray(signals.v, float)
    rate = np.gradient(v, t)
    fig, ax = plt.subplots(2, 2, figsize=(10, 7), constrained_layout=True)
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
    up = rate > 0
    ax[0, 1].scatter(v[up], res[up], s=2, label="loading")
    ax[0, 1].scatter(v[~up], res[~up], s=2, label="unloading/hold")
    ax[0, 1].set(xlabel="input (counts)", ylabel="residual (deg)", title="residual vs input")
    ax[0, 1].legend(fontsize=8, markerscale=4)
    ax[1, 0].scatter(rate, res, s=2, color="tab:green")
    ax[1, 0].set(xlabel="input rate (counts/s)", ylabel="residual (deg)", title="residual vs rate")
    ax[1, 1].plot(v, theta, ".", ms=2, color="0.5", label="measured")
    ax[1, 1].plot(v, y, lw=0.8, color="tab:red", label="model")
    ax[1, 1].set(xlabel="input (counts)", ylabel="angle (deg)", title="angle vs input")
    ax[1, 1].legend(fontsize=8)
    fig.suptitle(title)
    return fig


def _save(fig, path: Path) -> None:
    import matplotlib.pyplot as plt

    from i2ris_calib.io.atomic import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90)
    plt.close(fig)


def diagnose_file(
    data: Path,
    axis: str,
    start: str = "egpi",
    out: Path | None = None,
    config=None,
    direction: str = "auto",
) -> dict:
    """Run the diagnosis on ``data`` and write ``out`` (see module doc). Returns diagnosis.json."""
    from rich.progress import Progress

    from i2ris_calib.config import PipelineConfig
    from i2ris_calib.diagnosis.report import diagnosis_markdown, diagnosis_record
    from i2ris_calib.diagnosis.serialize import model_to_dict
    from i2ris_calib.diagnosis.workflow import diagnose, fit_start_model, single_threaded_blas
    from i2ris_calib.io.atomic import atomic_dir, write_json, write_text
    from i2ris_calib.io.provenance import provenance

    if start not in STARTS:
        raise CalibError(f"--start must be gpi or egpi, got '{start}'")
    cfg = config or PipelineConfig()
    out = Path(out) if out is not None else Path("diagnose_out")
    signals, theta, abs_input = read_synced(Path(data), axis, direction, cfg.fit.zero_band_counts)
    with Progress(transient=True) as bar, single_threaded_blas():
        task = bar.add_task(f"diagnose {axis}: fitting {start}", total=None)
        base = fit_start_model(start, signals, theta, cfg.diagnose, cfg.fit)
        diag = diagnose(
            base,
            signals,
            theta,
            cfg.diagnose,
            progress=lambda name: bar.update(task, description=f"diagnose {axis}: {name}"),
        )
    models = [diag.start_model] + [s.model_after for s in diag.steps]
    labels = ["start"] + [s.effect for s in diag.steps]
    figures = [f"residual_{i:02d}_{lab}.png" for i, lab in enumerate(labels)]
    record = diagnosis_record(diag, figures)
    record.update(
        schema=SCHEMA,
        axis=axis,
        start=start,
        source=str(data),
        direction="-" if abs_input else "+",
        abs_input=abs_input,
        n_samples=int(theta.size),
        provenance=provenance([data], cfg),
    )
    theta_plot = np.asarray(theta, float)
    with atomic_dir(out) as tmp:
        for i, (m, name) in enumerate(zip(models, figures, strict=True)):
            title = f"{axis}: {' + '.join([start, *labels[1 : i + 1]])}"
            _save(_figure(m, signals, theta_plot, diag.holdout, title), tmp / name)
        write_json(tmp / "diagnosis.json", record)
        final = model_to_dict(diag.final_model)
        final.update(axis=axis, abs_input=abs_input)
        write_json(tmp / "final_model.json", final)
        write_text(tmp / "diagnosis.md", diagnosis_markdown(record))
    return record
