"""Build small synthetic run folders exactly per the documented contracts (docs/formats.md), with known truth.

Every number the report shows is computed here from known functions, independently
of the code under test, and returned in a ``Truth`` dict so tests can compare.
"""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pandas as pd

# The stage outputs a run folder normally holds (diagnosis is optional).
STAGE_FILES = (
    "track/angles.csv",
    "track/track.json",
    "sync/sync.json",
    "sync/synced.csv",
    "fit/yaw/fit.json",
    "fit/pitch/fit.json",
)
FPS = 30.0
N_FRAMES = 600
FLAGGED = {"not_found": range(100, 130), "ambiguous": range(300, 310), "rejected": range(450, 455)}
OFFSET_S, DRIFT_PPM = 0.25, 15.0
OFFSET_SE_S, DRIFT_SE_PPM = 0.0004, 2.5


def tiny_png(width: int = 8, height: int = 6, rgb: tuple[int, int, int] = (200, 30, 30)) -> bytes:
    """A valid solid-colour RGB PNG built by hand (zlib + CRC chunks)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    raw = b"".join(b"\x00" + bytes(rgb) * width for _ in range(height))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


def paper_metrics(theta: np.ndarray, pred: np.ndarray) -> dict[str, float]:
    """RMSE (deg), NRMSE (%), max abs error (deg), paper Eq25-27."""
    err = pred - theta
    rmse = float(np.sqrt(np.mean(err**2)))
    return {
        "rmse_deg": rmse,
        "nrmse_pct": 100.0 * rmse / float(theta.max() - theta.min()),
        "max_abs_err_deg": float(np.max(np.abs(err))),
    }


def _prov(inputs: dict[str, str] | None = None, **config) -> dict:
    return {
        "package": "i2ris-calib",
        "version": "0.1.0",
        "python": "3.11.2",
        "config": config or {"seed": 1},
        "inputs": inputs or {"x.csv": "ab" * 32},
    }


def write_track(root: Path) -> dict:
    """track/angles.csv + track.json; returns truth (counts, detection rate, reproj stats)."""
    frame = np.arange(N_FRAMES)
    t = frame / FPS + 0.5
    status = np.array(["measured"] * N_FRAMES, dtype=object)
    for s, idx in FLAGGED.items():
        status[list(idx)] = s
    measured = status == "measured"
    yaw = np.where(measured, 30 * np.sin(2 * np.pi * t / 10), np.nan)
    pitch = np.where(measured, 20 * np.sin(2 * np.pi * t / 8), np.nan)
    err = np.full(N_FRAMES, np.nan)
    err[measured] = np.linspace(0.1, 1.1, int(measured.sum()))
    gray = np.where((t > 1.0) & (t < 1.2), 220.0, 80.0)
    df = pd.DataFrame(
        {
            "frame": frame,
            "time_s": t,
            "yaw_deg": yaw,
            "pitch_deg": pitch,
            "status": status,
            "reproj_err_px": err,
            "mean_gray_top": gray,
            "mean_gray_side": gray - 3,
        }
    )
    (root / "track").mkdir(parents=True, exist_ok=True)
    df.to_csv(root / "track" / "angles.csv", index=False)
    counts = {
        s: int((status == s).sum()) for s in ("measured", "not_found", "ambiguous", "rejected")
    }
    n_meas = counts["measured"]
    summary = {
        "n_frames": N_FRAMES,
        "counts": counts,
        "detection_rate": n_meas / N_FRAMES,
        "reproj_err_px": {"median": 0.6, "p95": 1.05, "max": 1.1},
        "provenance": _prov({"top.mkv": "11" * 32, "side.mkv": "22" * 32}, camera="top"),
    }
    (root / "track" / "track.json").write_text(json.dumps(summary, indent=2))
    return {
        "counts": counts,
        "detection_rate": n_meas / N_FRAMES,
        "reproj_median_px": 0.6,
        "reproj_p95_px": 1.05,
        "reproj_max_px": 1.1,
        "duration_s": (N_FRAMES - 1) / FPS,
    }


def write_sync(root: Path) -> dict:
    """sync/sync.json + synced.csv built from the clock model t_ctrl = off + (1+d) t_cam."""
    t_cam = np.arange(N_FRAMES) / FPS + 0.5
    t_ctrl = OFFSET_S + (1 + DRIFT_PPM * 1e-6) * t_cam
    enc_yaw = np.round(1500 * np.sin(2 * np.pi * t_ctrl / 10)).astype(int)
    enc_pitch = np.round(1000 * np.sin(2 * np.pi * t_ctrl / 8)).astype(int)
    yaw = 0.02 * enc_yaw + 1.0 * np.sign(np.gradient(enc_yaw.astype(float)))
    pitch = 0.02 * enc_pitch + 0.8 * np.sign(np.gradient(enc_pitch.astype(float)))
    df = pd.DataFrame(
        {
            "time_s": t_ctrl,
            "enc_yaw": enc_yaw,
            "enc_pitch": enc_pitch,
            "yaw_deg": yaw,
            "pitch_deg": pitch,
            "status": "measured",
            "frame": np.arange(N_FRAMES),
        }
    )
    (root / "sync").mkdir(parents=True, exist_ok=True)
    df.to_csv(root / "sync" / "synced.csv", index=False)
    sync = {
        "offset_s": OFFSET_S,
        "drift_ppm": DRIFT_PPM,
        "offset_stderr_s": OFFSET_SE_S,
        "drift_stderr_ppm": DRIFT_SE_PPM,
        "method": "event",
        "n_events": 3,
        "provenance": _prov({"encoders.csv": "33" * 32}),
    }
    (root / "sync" / "sync.json").write_text(json.dumps(sync, indent=2))
    return sync


GPI_PARAMS = ("a1", "a2", "a3", "a4", "lam", "sigma", "r1", "rn")
EGPI_PARAMS = ("a1", "a2", "a3", "a4", "a5", "a6", "lam", "sigma", "r1", "rn", "kappa", "v_f")


UNMEASURED_S = (12.0, 12.3)  # own "+" samples with no angle (tracking lost)
GAP_S = (16.0, 16.5)  # rows missing from the recording (a "-" excursion)
HOLDOUT_FROM_S = 20.0  # own samples from here on are held out


def recording(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Known signed input and angle of one axis: (t, enc, angle), rows in GAP_S removed.

    ``enc`` alternates "+" and "-" excursions of 5 s (period 10 s); the angle is linear
    with a +-1.5 deg backlash, 1.2x steeper on the "-" side; NaN during UNMEASURED_S.
    """
    t = t[~((t >= GAP_S[0]) & (t < GAP_S[1]))]
    enc = 1000 * np.sin(2 * np.pi * t / 10) * (1 - 0.02 * t)
    side = np.where(enc >= 0, 1.0, 1.2)
    angle = side * (0.03 * enc + 1.5 * np.sign(enc) * np.sign(np.gradient(np.abs(enc))))
    angle[(t >= UNMEASURED_S[0]) & (t < UNMEASURED_S[1])] = np.nan
    return t, enc, angle


def _dataset(axis: str, direction: str, t: np.ndarray, scale: float = 1.0):
    """One dataset over the whole recording, in the fit stage's conventions.

    ``v = max(enc, 0)`` ("+") or ``max(-enc, 0)`` ("-"); ``theta_deg`` = angle ("+") or
    -angle ("-") on every measured sample; split: "other" outside the direction, else
    "holdout" from HOLDOUT_FROM_S on, else "fit". Models = theta + known errors (GPI
    1.2 sin, EGPI 0.2 sin, EGPI_C 0.4 sin, period 2.5 s); metrics over own measured samples.
    """
    t, enc, angle = recording(t)
    sign = -1.0 if direction == "-" else 1.0
    v = np.maximum(sign * enc, 0.0)
    theta = scale * sign * angle
    own = enc >= 0 if direction == "+" else enc < 0
    phase = 2 * np.pi * t / 2.5
    gpi = theta + 1.2 * np.sin(phase)
    egpi = theta + 0.2 * np.sin(phase + 1)
    egpi_c = theta + 0.4 * np.sin(phase + 2)
    split = np.where(~own, "other", np.where(t >= HOLDOUT_FROM_S, "holdout", "fit"))
    name = f"{axis}{direction}"
    pred = pd.DataFrame(
        {
            "dataset": name,
            "time_s": t,
            "v": v,
            "theta_deg": theta,
            "gpi_deg": gpi,
            "egpi_deg": egpi,
            "egpi_c_deg": egpi_c,
            "split": split,
        }
    )
    measured = np.isfinite(theta)
    fit_m, hold_m = (split == "fit") & measured, (split == "holdout") & measured

    def record(y: np.ndarray, names: tuple[str, ...], seed: int) -> dict:
        rng = np.random.default_rng(seed)
        params = {
            n: float(v) for n, v in zip(names, rng.uniform(0.05, 2.0, len(names)), strict=True)
        }
        stderr = {n: 0.01 * params[n] for n in names}
        stderr[names[-1]] = None  # not estimable
        return {
            "params": params,
            "stderr": stderr,
            "metrics": paper_metrics(theta[fit_m], y[fit_m]),
            "holdout_metrics": paper_metrics(theta[hold_m], y[hold_m]),
            "aic": -100.0 - seed,
            "bic": -90.0 - seed,
            "converged": True,
            "message": "`xtol` termination condition is satisfied.",
            "nfev": 40 + seed,
            "n_samples": int(fit_m.sum()),
            "v_f": 640.0,
        }

    ds = {
        "name": name,
        "direction": direction,
        "abs_fitted": direction == "-",
        "source": f"sync/synced_{name}.csv",
        "n_samples": len(t),
        "rows": {
            "total": len(t),
            "in_direction": int(own.sum()),
            "angle_missing": int((own & ~measured).sum()),
            "holdout": int(hold_m.sum()),
            "fitted": int(fit_m.sum()),
        },
        "bands": {
            "zero_band": 5.0,
            "deadband": 1.8,
            "input_noise": 0.6,
            "derived": ["deadband"],
        },
        "models": {
            "gpi": record(gpi, GPI_PARAMS, 1),
            "egpi": record(egpi, EGPI_PARAMS, 2),
            "egpi_c": record(egpi_c, EGPI_PARAMS, 3),
        },
    }
    return ds, pred


def write_fit(root: Path, axis: str, predictions: bool = True) -> dict:
    """fit/<axis>/fit.json (+ predictions.csv) with a '+' and a '-' dataset."""
    t = np.round(np.arange(0, 30, 0.02), 6)
    dsp, pp = _dataset(axis, "+", t, 1.0)
    dsm, pm = _dataset(axis, "-", t, 1.0)
    fit = {
        "schema": "i2ris-calib.fit/1",
        "axis": axis,
        "datasets": [dsp, dsm],
        "provenance": _prov({f"sync/synced_{axis}.csv": "44" * 32}, n_thresholds=30),
    }
    folder = root / "fit" / axis
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "fit.json").write_text(json.dumps(fit, indent=2))
    if predictions:
        pd.concat([pp, pm]).to_csv(folder / "predictions.csv", index=False)
    return fit


DIAG_MD = """# Diagnosis: {axis}

The residual is concentrated on the unloading branch below 400 counts.

![residual before step 1](plots/step1_before.png)

<script>alert('x')</script>

| step | effect | held-out RMSE |
|---|---|---|
| 1 | axis_coupling | 0.91 -> 0.31 |
"""


def write_diagnosis(root: Path, axis: str = "yaw", with_missing_image: bool = False) -> dict:
    """diagnose/<axis>/diagnosis.json + diagnosis.md + two PNGs (one referenced by the md)."""
    folder = root / "diagnose" / axis
    (folder / "plots").mkdir(parents=True, exist_ok=True)
    (folder / "plots" / "step1_before.png").write_bytes(tiny_png(8, 6, (200, 30, 30)))
    (folder / "plots" / "step1_after.png").write_bytes(tiny_png(10, 5, (30, 30, 200)))
    plots = ["plots/step1_before.png", "plots/step1_after.png"]
    if with_missing_image:
        plots.append("plots/gone.png")
    diag = {
        "axis": axis,
        "baseline": {"rmse_deg": 0.85, "holdout_rmse_deg": 0.91},
        "final": {"rmse_deg": 0.30, "holdout_rmse_deg": 0.31},
        "named_effects": ["axis_coupling"],
        "steps": [
            {
                "effect": "axis_coupling",
                "params": {"c_deg_per_count": 0.001},
                "holdout_rmse_before_deg": 0.91,
                "holdout_rmse_after_deg": 0.31,
                "delta_bic": -250.0,
                "evidence": "held-out RMSE -66 %",
                "plots": plots,
            }
        ],
        "provenance": _prov({"sync/synced.csv": "55" * 32}),
    }
    (folder / "diagnosis.json").write_text(json.dumps(diag, indent=2))
    (folder / "diagnosis.md").write_text(DIAG_MD.format(axis=axis))
    return diag


def make_run_folder(
    root: Path,
    track: bool = True,
    sync: bool = True,
    fit_axes: tuple[str, ...] = ("yaw", "pitch"),
    predictions: bool = True,
    diagnosis: bool = False,
) -> dict:
    """A complete (or partial) run folder; returns the truth written into it."""
    root.mkdir(parents=True, exist_ok=True)
    truth: dict = {}
    if track:
        truth["track"] = write_track(root)
    if sync:
        truth["sync"] = write_sync(root)
    truth["fit"] = {a: write_fit(root, a, predictions) for a in fit_axes}
    if diagnosis:
        truth["diagnosis"] = write_diagnosis(root)
    return truth
