"""The whole-history truth and the excursion motion: the truth IS the data layer's model."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.data.dataset import direction_datasets
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.simulation import trajectory as tj
from i2ris_calib.simulation.presets import preset_config
from i2ris_calib.simulation.truth import session_truth, truth_at


def _exact_cfg(seed: int, **kw):
    return preset_config("exact_ci", seed=seed, **kw)


def _model_error(axis: str, t: np.ndarray, enc: np.ndarray, theta: np.ndarray, params: dict):
    """Max |EGPI(data layer dataset) - truth| over each direction's samples, per direction."""
    out = {}
    for ds in direction_datasets(axis, t, enc, theta):
        m = model_from_params("egpi", params[ds.name], 30, ds.bands.deadband)
        pred = np.asarray(m(ds.signals))
        ok = np.isfinite(ds.theta_deg)
        assert ok.sum() > 100
        out[ds.name] = float(np.max(np.abs(pred[ok] - ds.theta_deg[ok])))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_truth_is_the_data_layers_model_on_the_fine_grid(seed):
    cfg = _exact_cfg(seed)
    tr = session_truth(cfg)
    for axis, enc, ang in (("yaw", tr.enc_yaw, tr.yaw_deg), ("pitch", tr.enc_pitch, tr.pitch_deg)):
        err = _model_error(axis, tr.t_s, enc.astype(float), ang, tr.params)
        assert sorted(err) == sorted([f"{axis}+", f"{axis}-"])
        assert max(err.values()) < 1e-9, err


@pytest.mark.parametrize("seed", [0, 3])
def test_truth_at_frame_times_is_exact_for_a_frame_rate_dataset(seed):
    # frames at 30 fps with a sub-ms phase: inputs interpolated as sync does, the
    # truth evaluated exactly there (no blend across the model's steps)
    cfg = _exact_cfg(seed)
    tr = session_truth(cfg)
    tq = np.arange(-0.5, tj.motion_duration_s(cfg) + 0.5, 1 / 30.0) + 0.000437
    # plus samples inside the 1 ms grid interval of every step of the truth (flag point,
    # direction change), where interpolating the grid would blend both sides
    steps = np.flatnonzero(
        (np.abs(np.diff(tr.yaw_deg)) > 0.3) | (np.abs(np.diff(tr.pitch_deg)) > 0.3)
    )
    assert steps.size >= 4
    tq = np.sort(np.concatenate([tq, tr.t_s[steps] + 0.0004]))
    yaw, pitch = truth_at(cfg, tr, tq)
    for axis, enc_grid, ang in (("yaw", tr.enc_yaw, yaw), ("pitch", tr.enc_pitch, pitch)):
        enc = np.interp(tq, tr.t_s, enc_grid.astype(float))
        err = _model_error(axis, tq, enc, ang, tr.params)
        assert max(err.values()) < 1e-9, err
    blend = np.interp(tq, tr.t_s, tr.yaw_deg)
    assert np.abs(blend - yaw).max() > 0.1  # the case the exact evaluation exists for


def test_whole_history_truth_has_steps_the_blocks_truth_fades():
    cfg = _exact_cfg(0)
    tr = session_truth(cfg)
    step = np.abs(np.diff(tr.yaw_deg)).max()
    assert step > 0.5  # the model's flag-point step / direction change (a 1 ms ramp is ~0.03)


@pytest.mark.parametrize("seed", [0, 1])
def test_zero_start_makes_the_rest_pose_zero(seed):
    tr = session_truth(_exact_cfg(seed))
    before = tr.t_s < cfg_rest(seed)
    assert np.abs(tr.yaw_deg[before]).max() < 1e-9
    assert np.abs(tr.pitch_deg[before]).max() < 1e-9
    off = session_truth(_exact_cfg(seed, zero_start=False))
    assert np.abs(off.yaw_deg[before]).min() > 0.05  # paper-like EGPI starts ~0.3-0.5 deg


def cfg_rest(seed: int) -> float:
    return _exact_cfg(seed).rest_s


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_excursions_hold_at_zero_go_negative_vary_speed_and_turn_with_pauses(seed):
    cfg = _exact_cfg(seed, compound_fraction=0.0)
    sched = tj.excursion_schedule(cfg)
    assert len(sched) == cfg.excursions * len(cfg.datasets)
    t = np.arange(0.0, tj.motion_duration_s(cfg), 0.001)
    ey, ep = tj.session_inputs(cfg, t)
    for e in sched:
        # negative excursions carry the sign; peaks inside the range; first/last full scale
        amp = cfg.amplitude_counts[0 if e.block.axis == "yaw" else 1]
        assert e.knots_v.max() <= amp + 1e-9 and e.knots_v[0] == 0 and e.knots_v[-1] == 0
    for name in cfg.datasets:
        mine = [e for e in sched if e.block.name == name]
        amp = cfg.amplitude_counts[0 if name.startswith("yaw") else 1]
        assert mine[0].knots_v.max() == amp and mine[-1].knots_v.max() == amp
        enc = ey if name.startswith("yaw") else ep
        sign = 1 if name.endswith("+") else -1
        assert (sign * enc).max() == amp
    # holds at zero between consecutive excursions (no compound moves here)
    for a, b in zip(sched[:-1], sched[1:], strict=True):
        gap = b.block.t0_s - a.block.t1_s
        assert gap >= cfg.hold_s[0] - 1e-9
        mid = (t > a.block.t1_s + 1e-3) & (t < b.block.t0_s - 1e-3)
        assert np.all(ey[mid] == 0) and np.all(ep[mid] == 0)
    # varied speeds: ramp slopes differ by more than 20 %
    slopes = np.concatenate([np.abs(np.diff(e.knots_v)) / np.diff(e.knots_t) for e in sched])
    slopes = slopes[slopes > 0]
    assert slopes.max() / slopes.min() > 1.2
    # every turning point is held >= 0.15 s (frame-rate sampling sees it)
    for e in sched:
        dv = np.diff(e.knots_v)
        flat = np.flatnonzero(dv == 0)
        turns = np.flatnonzero(np.sign(dv[:-1]) * np.sign(dv[1:]) < 0)
        assert turns.size == 0  # a turn always has a pause between
        assert np.all(np.diff(e.knots_t)[flat] >= 0.15 - 1e-12)


def test_compound_moves_drive_both_axes_each_angle_from_its_own_input():
    cfg = _exact_cfg(0, compound_fraction=1.0)
    sched = tj.excursion_schedule(cfg)
    overlap = [
        (a, b)
        for a in sched
        for b in sched
        if a.block.axis == "yaw"
        and b.block.axis == "pitch"
        and a.block.t0_s < b.block.t1_s
        and b.block.t0_s < a.block.t1_s
    ]
    assert overlap
    tr = session_truth(cfg)
    both = (np.abs(tr.enc_yaw) > 100) & (np.abs(tr.enc_pitch) > 100)
    assert both.sum() > 1000
    # each axis's angle is its own models on its own input, also while both move
    for axis, enc, ang in (("yaw", tr.enc_yaw, tr.yaw_deg), ("pitch", tr.enc_pitch, tr.pitch_deg)):
        err = _model_error(axis, tr.t_s, enc.astype(float), ang, tr.params)
        assert max(err.values()) < 1e-9


def test_schedule_is_deterministic_and_seeded():
    a = tj.excursion_schedule(_exact_cfg(5))
    b = tj.excursion_schedule(_exact_cfg(5))
    c = tj.excursion_schedule(_exact_cfg(6))
    assert [e.block for e in a] == [e.block for e in b]
    assert [e.block for e in a] != [e.block for e in c]


def test_blocks_truth_unchanged_by_truth_at():
    cfg = preset_config("ci", truth="blocks")
    tr = session_truth(cfg)
    tq = np.linspace(0.0, tj.motion_duration_s(cfg), 777) + 1e-4
    y, p = truth_at(cfg, tr, tq)
    assert np.array_equal(y, np.interp(tq, tr.t_s, tr.yaw_deg))
    assert np.array_equal(p, np.interp(tq, tr.t_s, tr.pitch_deg))


def test_hidden_effect_changes_the_whole_history_truth():
    base = session_truth(_exact_cfg(0))
    delayed = session_truth(_exact_cfg(0, effects={"time_delay": {"tau_s": 0.2}}))
    assert np.abs(base.yaw_deg - delayed.yaw_deg).max() > 1.0


def test_bad_motion_settings_are_refused():
    with pytest.raises(ValueError, match="excursions"):
        preset_config("exact_ci", excursions=1)
    with pytest.raises(ValueError, match="truth"):
        preset_config("exact_ci", truth="faded")
