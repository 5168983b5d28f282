"""Locate the disagreement: where (branch, input range, time, rate, lag) the residual lives.

:func:`residual_analysis` returns plain numbers (JSON-ready) and
:func:`concentration_sentences` turns them into one-line statements with numbers
for the report. Residual = measured - model (deg).
"""

from __future__ import annotations

import numpy as np

from i2ris_calib.model import Signals


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        return float("nan")
    a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
    den = float(np.sqrt(np.dot(a, a) * np.dot(b, b)))
    return float(np.dot(a, b) / den) if den > 0 else float("nan")


def _cell(res: np.ndarray, sel: np.ndarray, total_sse: float) -> dict:
    r = res[sel]
    n = int(r.size)
    sse = float(np.dot(r, r)) if n else 0.0
    return {
        "n": n,
        "rmse_deg": float(np.sqrt(sse / n)) if n else float("nan"),
        "mean_deg": float(r.mean()) if n else float("nan"),
        "sse_share": sse / total_sse if total_sse > 0 else 0.0,
        "sample_share": n / res.size if res.size else 0.0,
    }


def branch_labels(loading: np.ndarray, rate: np.ndarray, hold_frac: float = 0.05) -> np.ndarray:
    """``"loading"``, ``"unloading"`` or ``"hold"`` per sample, shape (n,).

    ``loading`` (bool, (n,)) is the model's ``v' > 0``
    (:func:`i2ris_calib.diagnosis.cycles.loading_mask`). A sample is a hold when its
    input speed is below ``hold_frac`` of the 95th percentile speed.
    """
    speed = np.abs(rate)
    ref = float(np.quantile(speed, 0.95)) if speed.size else 0.0
    lab = np.where(np.asarray(loading, bool), "loading", "unloading").astype(object)
    lab[speed < hold_frac * ref] = "hold"
    return lab


def residual_analysis(
    res: np.ndarray,
    signals: Signals,
    loading: np.ndarray,
    n_bins: int = 8,
    max_lag_s: float = 1.0,
) -> dict:
    """Numbers describing where the residual is concentrated.

    Parameters
    ----------
    res : ndarray, shape (n,)
        Measured minus model angle (deg); NaN where not measured.
    signals : Signals
        Inputs of the model, shape (n,); ``t_s`` is needed for rate, time and lag
        analyses (sample index is used when it is missing).
    loading : ndarray of bool, shape (n,)
        Loading branch of ``signals.v`` (:func:`i2ris_calib.diagnosis.cycles.loading_mask`).
    n_bins : int
        Input bins (quantiles) per branch and time windows.
    max_lag_s : float
        Largest lag of the cross-correlation with the input (s).

    Returns
    -------
    dict
        ``rmse_deg``, ``by_branch``, ``by_input`` (list of cells with branch and
        input range), ``by_time`` (windows), ``by_rate`` (terciles of speed and
        correlations), ``other_axis`` (correlations), ``autocorr`` (at lags of 1,
        5, 20 samples and 1 s, plus the Durbin-Watson statistic) and
        ``xcorr_input`` (correlation of the residual with the input and with its
        rate shifted by each lag; peak lag in s).
    """
    v = np.asarray(signals.v, float)
    n = v.size
    t = np.asarray(signals.t_s, float) if signals.t_s is not None else np.arange(n, dtype=float)
    ok = np.isfinite(res)
    r0 = np.where(ok, res, 0.0)
    total = float(np.dot(r0, r0))
    rate = np.gradient(v, t) if n > 1 else np.zeros(n)
    lab = branch_labels(loading, rate)
    out: dict = {"rmse_deg": float(np.sqrt(total / max(ok.sum(), 1))), "n": int(ok.sum())}
    out["by_branch"] = {
        b: _cell(res[ok], lab[ok] == b, total) for b in ("loading", "unloading", "hold")
    }
    out["by_input"] = _input_cells(res, v, lab, ok, total, n_bins)
    out["by_time"] = _time_windows(res, t, ok, total, n_bins)
    out["by_rate"] = _rate_cells(res, rate, ok, total)
    out["other_axis"] = {
        "corr_res_theta_other": _corr(res, np.asarray(signals.theta_other_deg, float))
        if signals.theta_other_deg is not None
        else None,
        "corr_res_v_other": _corr(res, np.asarray(signals.v_other, float))
        if signals.v_other is not None
        else None,
    }
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    out["autocorr"] = _autocorrelations(res, dt, total)
    out["xcorr_input"] = _xcorr_input(res, v, rate, dt, max_lag_s)
    return out


def _input_cells(res, v, lab, ok, total: float, n_bins: int) -> list[dict]:
    """The residual's cells by branch (loading, unloading) and input quantile bin."""
    cells = []
    edges = np.unique(np.quantile(v[ok], np.linspace(0, 1, n_bins + 1))) if ok.any() else []
    for b in ("loading", "unloading"):
        for lo, hi in zip(edges[:-1], edges[1:], strict=False):
            sel = (lab[ok] == b) & (v[ok] >= lo) & (v[ok] <= hi)
            c = _cell(res[ok], sel, total)
            c.update(branch=b, v_lo_counts=float(lo), v_hi_counts=float(hi))
            cells.append(c)
    return cells


def _time_windows(res, t, ok, total: float, n_bins: int) -> list[dict]:
    """The residual's cells in ``n_bins`` equal time windows (s) over the counted
    samples (``ok``; not a pre-history or burn-in before them)."""
    span = t[ok] if np.any(ok) else t
    tw = np.linspace(span[0], span[-1], n_bins + 1) if span.size else []
    windows = []
    for lo, hi in zip(tw[:-1], tw[1:], strict=False):
        c = _cell(res[ok], (t[ok] >= lo) & (t[ok] <= hi), total)
        c.update(t_lo_s=float(lo), t_hi_s=float(hi))
        windows.append(c)
    return windows


def _rate_cells(res, rate, ok, total: float) -> dict:
    """The residual's cells by terciles of the input speed (counts/s), and its
    correlations with the rate and (absolute) with the speed."""
    speed = np.abs(rate)
    qs = np.quantile(speed[ok], [0, 1 / 3, 2 / 3, 1]) if ok.any() else [0, 0, 0, 0]
    terc = []
    for i in range(3):
        c = _cell(res[ok], (speed[ok] >= qs[i]) & (speed[ok] <= qs[i + 1]), total)
        c.update(speed_lo_counts_per_s=float(qs[i]), speed_hi_counts_per_s=float(qs[i + 1]))
        terc.append(c)
    return {
        "terciles": terc,
        "corr_res_rate": _corr(res, rate),
        "corr_absres_speed": _corr(np.abs(res), speed),
    }


def _autocorrelations(res, dt: float, total: float) -> dict:
    """The residual's autocorrelation at lags of 1, 5, 20 samples and 1 s (pairs with
    an unmeasured sample left out rather than zero-filled) and the Durbin-Watson
    statistic."""
    n = res.size
    lags = {"1": 1, "5": 5, "20": 20, "1s": max(1, round(1.0 / dt))}
    out = {f"lag_{k}": _corr(res[m:], res[:-m]) if 0 < m < n else None for k, m in lags.items()}
    d = np.diff(res)
    d = d[np.isfinite(d)]
    out["durbin_watson"] = float(np.dot(d, d) / total) if total > 0 else None
    return out


def _xcorr_input(res, v, rate, dt, max_lag_s, n_lags: int = 11) -> dict:
    """Correlation of res[k] with v[k - L] and rate[k - L] for lags L in s (lags of
    fewer samples than the series; an empty series: no lags, peak NaN)."""
    m_max = max(1, min(round(max_lag_s / dt), res.size - 1))
    steps = np.unique(np.round(np.linspace(-m_max, m_max, 2 * n_lags + 1)).astype(int))
    steps = steps[np.abs(steps) < res.size]
    if not steps.size:
        return {"lags": [], "peak_rate_lag_s": float("nan"), "peak_rate_corr": float("nan")}
    rows = []
    for m in steps:
        if m >= 0:
            a, bv, br = res[m:], v[: v.size - m], rate[: rate.size - m]
        else:
            a, bv, br = res[:m], v[-m:], rate[-m:]
        rows.append({"lag_s": float(m * dt), "corr_input": _corr(a, bv), "corr_rate": _corr(a, br)})
    best = max(rows, key=lambda r: abs(r["corr_rate"]) if np.isfinite(r["corr_rate"]) else -1)
    return {"lags": rows, "peak_rate_lag_s": best["lag_s"], "peak_rate_corr": best["corr_rate"]}


def concentration_sentences(a: dict) -> list[str]:
    """One-line statements, with numbers, of where the disagreement is concentrated."""
    out = [f"residual RMSE {a['rmse_deg']:.3g} deg over {a['n']} samples"]
    out.append(_branch_sentence(a["by_branch"]))
    cells = [c for c in a["by_input"] if c["n"] > 0]
    if cells:
        out.append(_input_cell_sentence(max(cells, key=lambda c: c["sse_share"])))
    w = max(a["by_time"], key=lambda c: c["rmse_deg"] if np.isfinite(c["rmse_deg"]) else -1)
    out.append(
        f"worst time window {w['t_lo_s']:.3g}-{w['t_hi_s']:.3g} s: RMSE {w['rmse_deg']:.3g} deg "
        f"({w['rmse_deg'] / a['rmse_deg']:.2g}x the overall RMSE)"
        if a["rmse_deg"] > 0
        else "residual is zero"
    )
    rr = a["by_rate"]
    out.append(
        f"residual vs input rate: correlation {rr['corr_res_rate']:+.2f}; |residual| vs speed "
        f"{rr['corr_absres_speed']:+.2f}; RMSE by speed tercile "
        + ", ".join(f"{c['rmse_deg']:.3g}" for c in rr["terciles"])
        + " deg"
    )
    out += _other_axis_sentences(a["other_axis"])
    ac = a["autocorr"]
    out.append(
        f"residual autocorrelation {ac['lag_1']:.2f} at lag 1, {ac['lag_1s']:.2f} at 1 s "
        "(about 0 for white noise: values near 1 mean a systematic misfit)"
        if ac.get("lag_1") is not None and ac.get("lag_1s") is not None
        else "residual autocorrelation not available"
    )
    xc = a["xcorr_input"]
    out.append(
        f"cross-correlation with the input rate peaks at lag {xc['peak_rate_lag_s']:+.3g} s "
        f"(r = {xc['peak_rate_corr']:+.2f})"
    )
    return out


def _branch_sentence(br: dict) -> str:
    """Where on the branches (loading, unloading, hold) the squared residual lies."""
    worst = max(br, key=lambda b: br[b]["sse_share"])
    return (
        f"{100 * br[worst]['sse_share']:.0f}% of the squared residual lies on the {worst} "
        f"branch ({100 * br[worst]['sample_share']:.0f}% of the samples, "
        f"RMSE {br[worst]['rmse_deg']:.3g} deg, mean {br[worst]['mean_deg']:+.3g} deg)"
    )


def _input_cell_sentence(c: dict) -> str:
    """The (branch, input bin) cell ``c`` holding the largest share of the residual."""
    return (
        f"largest input cell: {c['branch']}, input {c['v_lo_counts']:.4g}-{c['v_hi_counts']:.4g}"
        f" counts holds {100 * c['sse_share']:.0f}% of the squared residual in "
        f"{100 * c['sample_share']:.0f}% of the samples (RMSE {c['rmse_deg']:.3g} deg)"
    )


def _other_axis_sentences(oa: dict) -> list[str]:
    """The residual's correlation with the other axis's angle and input (when known)."""
    parts = []
    if oa["corr_res_theta_other"] is not None:
        parts.append(f"other axis angle {oa['corr_res_theta_other']:+.2f}")
    if oa["corr_res_v_other"] is not None:
        parts.append(f"other axis input {oa['corr_res_v_other']:+.2f}")
    return ["residual correlation with " + ", ".join(parts)] if parts else []
