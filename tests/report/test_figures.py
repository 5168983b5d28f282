"""Figures: fixed pixel sizes, determinism, degraded inputs; helper invariants."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from runfolder import _dataset

from i2ris_calib.report import figures
from i2ris_calib.report.render import png_size


@pytest.fixture(scope="module")
def pred() -> pd.DataFrame:
    return _dataset("yaw", "+", np.arange(0, 30, 0.05), 1.0)[1]


def test_fit_figure_has_fixed_size_and_is_deterministic(pred):
    a = figures.fit_figure_png(pred, "yaw+", "yaw", "+", dpi=50)
    b = figures.fit_figure_png(pred, "yaw+", "yaw", "+", dpi=50)
    assert png_size(a) == (600, 180)  # 12 x 3.6 in at 50 dpi
    assert a == b


def test_fit_figure_depends_on_data(pred):
    a = figures.fit_figure_png(pred, "yaw+", "yaw", "+", dpi=50)
    other = pred.assign(egpi_c_deg=pred["egpi_c_deg"] + 5.0)
    assert figures.fit_figure_png(other, "yaw+", "yaw", "+", dpi=50) != a
    # the other direction's samples are not drawn: changing them changes nothing ...
    o = pred["split"] == "other"
    assert o.any()
    hidden = pred.assign(theta_deg=pred["theta_deg"].where(~o, 99.0))
    assert figures.fit_figure_png(hidden, "yaw+", "yaw", "+", dpi=50) == a


def test_fit_figure_without_models_and_legacy_splits(pred):
    no_egpi = pred.drop(columns=["egpi_deg", "egpi_c_deg"]).assign(gpi_deg=np.nan)
    png = figures.fit_figure_png(no_egpi, "yaw-", "yaw", "-", dpi=40)
    assert png_size(png) == (480, 144)
    # an older predictions.csv: own samples only, no "other" rows, no egpi_c_deg
    old = pred[pred["split"] != "other"].drop(columns=["egpi_c_deg"])
    assert png_size(figures.fit_figure_png(old, "yaw+", "yaw", "+", dpi=40)) == (480, 144)


def _gappy_frame() -> pd.DataFrame:
    """100 samples at 10 Hz: rows 30-49 the other direction, row 70 not measured,
    rows 80-84 missing from the recording (a time gap), rows 60-69 held out."""
    t = np.round(np.arange(100) * 0.1, 6)
    theta = np.sin(t)
    theta[70] = np.nan
    split = np.array(["fit"] * 100, dtype=object)
    split[30:50] = "other"
    split[60:70] = "holdout"
    frame = pd.DataFrame(
        {
            "dataset": "yaw+",
            "time_s": t,
            "v": 100 * t,
            "theta_deg": theta,
            "gpi_deg": np.sin(t) + 1.0,
            "egpi_deg": np.sin(t) + 0.1,
            "egpi_c_deg": np.sin(t) + 0.2,
            "split": split,
        }
    )
    return frame.drop(index=range(80, 85)).sample(frac=1.0, random_state=3)  # any row order


def _runs(x: np.ndarray) -> list[tuple[float, float]]:
    """(first, last) of each NaN-separated run of ``x``."""
    out, start = [], None
    for i, val in enumerate(x):
        if np.isnan(val):
            if start is not None:
                out.append((x[start], x[i - 1]))
            start = None
        elif start is None:
            start = i
    if start is not None:
        out.append((x[start], x[-1]))
    return out


def test_fig6_data_breaks_lines_at_every_gap():
    d = figures.fig6_data(_gappy_frame())
    # model curves: own samples only, broken at the other stretch and at the time gap
    assert _runs(d.time_s) == [(0.0, 2.9), (5.0, 7.9), (8.5, 9.9)]
    assert np.array_equal(np.isnan(d.time_s), np.isnan(d.v))
    for col in ("gpi_deg", "egpi_deg", "egpi_c_deg"):
        y = d.models[col]
        assert np.array_equal(np.isnan(y), np.isnan(d.time_s))
        ok = ~np.isnan(y)
        assert np.allclose(
            y[ok] - np.sin(d.time_s[ok]), {"gpi_deg": 1.0, "egpi_deg": 0.1, "egpi_c_deg": 0.2}[col]
        )
    # model at the unmeasured sample (row 70) is drawn: the model is defined there
    assert np.any(np.isclose(d.time_s, 7.0))
    # measured and error: also broken at the unmeasured row 70
    assert _runs(d.meas_time_s) == [(0.0, 2.9), (5.0, 6.9), (7.1, 7.9), (8.5, 9.9)]
    assert np.allclose(np.nan_to_num(d.errors["gpi_deg"] - 1.0), 0.0)
    assert np.array_equal(np.isnan(d.errors["gpi_deg"]), np.isnan(d.meas_time_s))
    assert d.other_spans == [(3.0, 4.9)]
    assert d.holdout_spans == [(6.0, 6.9)]
    assert d.counts == {"fit": 64, "holdout": 10, "not_measured": 1, "other": 20}


def test_fig6_data_keeps_breaks_when_thinned():
    d = figures.fig6_data(_gappy_frame(), max_points=20)  # every 4th own sample
    runs = _runs(d.time_s)
    assert len(runs) == 3
    # no run crosses the other stretch (3.0-4.9 s) or the gap (8.0-8.4 s)
    for a, b in runs:
        assert not (a < 3.0 and b > 4.9) and not (a < 8.0 and b > 8.4)
    assert np.count_nonzero(~np.isnan(d.time_s)) <= 20


def test_continuation_gap_rule():
    t = np.array([0.0, 0.1, 0.2, 0.36, 0.46, 0.5, 0.6])
    keep = np.array([1, 1, 1, 1, 1, 0, 1], dtype=bool)
    # median step 0.1 -> a step of 0.16 is a gap at factor 1.5 but not at 2
    assert figures.continuation(t, keep, 1.5).tolist() == [0, 1, 1, 0, 1, 0, 0]
    assert figures.continuation(t, keep, 2.0).tolist() == [0, 1, 1, 1, 1, 0, 0]
    assert figures.continuation(t[:1], keep[:1]).tolist() == [False]


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.tuples(st.floats(0.01, 1.0), st.booleans()), min_size=1, max_size=80),
    st.integers(1, 7),
)
def test_broken_series_never_joins_across_a_dropped_sample(steps, k):
    """Two drawn points are joined only when no sample between them is dropped or gapped."""
    t = np.cumsum([dt for dt, _ in steps])
    keep = np.array([kp for _, kp in steps], dtype=bool)
    cont = figures.continuation(t, keep)
    idx = np.flatnonzero(keep)[::k]
    (rows,) = figures.broken_series(idx, cont, np.arange(t.size, dtype=float))
    assert np.count_nonzero(~np.isnan(rows)) == idx.size
    for a, b in zip(rows[:-1], rows[1:], strict=True):
        if np.isnan(a) or np.isnan(b):
            continue
        assert cont[int(a) + 1 : int(b) + 1].all()  # joined -> continuous in between
    # and a break only where one is needed
    n_breaks = int(np.isnan(rows).sum())
    needed = sum(not cont[a + 1 : b + 1].all() for a, b in zip(idx[:-1], idx[1:], strict=True))
    assert n_breaks == needed


def test_tracking_figure_without_flags_or_reprojection():
    a = pd.DataFrame(
        {
            "time_s": np.arange(50) / 30,
            "yaw_deg": np.arange(50.0),
            "pitch_deg": 0.0,
            "status": "measured",
        }
    )
    png = figures.tracking_figure_png(a, 1.0, dpi=40)
    assert png_size(png) == (400, 240)
    # with a roll column a fourth panel: 7 in high
    png = figures.tracking_figure_png(a.assign(roll_deg=0.01), 1.0, dpi=40)
    assert png_size(png) == (400, 280)


def test_synced_figure_size():
    s = pd.DataFrame(
        {"enc_yaw": np.arange(20), "enc_pitch": np.arange(20), "yaw_deg": 1.0, "pitch_deg": 2.0}
    )
    assert png_size(figures.synced_figure_png(s, dpi=40)) == (400, 144)


def test_holdout_spans():
    t = np.arange(10.0)
    h = np.array([0, 0, 1, 1, 0, 0, 0, 1, 1, 1], dtype=bool)
    assert figures.holdout_spans(t, h) == [(2.0, 3.0), (7.0, 9.0)]
    assert figures.holdout_spans(t, np.zeros(10, bool)) == []
    assert figures.holdout_spans(t[:0], h[:0]) == []


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0, 100, allow_nan=False), min_size=1, max_size=60),
    st.floats(0.01, 50),
    st.integers(0, 2**32 - 1),
)
def test_detection_rate_matches_brute_force(times, window, seed):
    t = np.sort(np.asarray(times))
    measured = np.random.default_rng(seed).random(t.size) < 0.7
    rate = figures.detection_rate(t, measured, window)
    for i, ti in enumerate(t):
        inside = (t >= ti - window / 2) & (t <= ti + window / 2)
        assert rate[i] == pytest.approx(measured[inside].mean(), abs=1e-12)
    assert np.all((rate >= 0) & (rate <= 1))


@given(st.integers(0, 10**6), st.integers(1, 10**5))
def test_thinning_step_bounds_points(n, max_points):
    k = figures.thinning_step(n, max_points)
    assert k >= 1 and len(range(0, n, k)) <= max(max_points, 1)
    if k > 1:
        assert len(range(0, n, k - 1)) > max_points  # smallest such step


def test_fig6_band_columns_are_carried_and_drawn(pred):
    """A ``<model>_sd_deg`` column becomes that model's band, broken at the same gaps."""
    band = pred.assign(egpi_sd_deg=0.05)
    data = figures.fig6_data(band)
    assert list(data.bands) == ["egpi_deg"]
    b = data.bands["egpi_deg"]
    assert b.shape == data.models["egpi_deg"].shape
    gaps = np.isnan(b)  # the break rows (the model may be NaN elsewhere too)
    assert gaps.any() and np.all(np.isnan(data.models["egpi_deg"])[gaps])
    assert np.nanmax(b) == np.nanmin(b) == 0.05
    assert figures.fig6_data(pred).bands == {}
    with_band = figures.fit_figure_png(band, "yaw+", "yaw", "+", dpi=40)
    assert with_band != figures.fit_figure_png(pred, "yaw+", "yaw", "+", dpi=40)
    assert png_size(with_band) == png_size(figures.fit_figure_png(pred, "yaw+", "yaw", "+", dpi=40))


def test_every_fitted_kind_has_a_curve_so_the_recommended_model_is_drawn():
    """Issue 32: Fig 6 drew only GPI and two-tendon GPI on a lab recording whose
    recommended model was Bouc-Wen; every kind of the registry has a curve now."""
    from i2ris_calib.hysteresis.registry import ALL_KINDS
    from i2ris_calib.report.figures import MODEL_CURVES

    assert {f"{k}_deg" for k in ALL_KINDS} <= {c for c, _, _ in MODEL_CURVES}
