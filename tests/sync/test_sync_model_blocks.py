"""The model method's data: whole frame history per axis (never spliced), honest sd."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.data.dataset import direction_of_samples, input_bands
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.sync.clock import clock_from_offsets
from i2ris_calib.sync.joint import (
    REST_KEEP_S,
    OffsetProfile,
    block_bias_cov,
    long_rest,
    long_run_covariance,
    map_times,
    model_blocks,
    nw_bandwidth,
)
from i2ris_calib.sync.log import make_encoder_log
from i2ris_calib.sync.xcorr import AxisSeries


def _signed_session(seed: int = 0):
    """Yaw +, hold at 0, -, hold, + (500 Hz log); 30 fps frames, some unmeasured."""
    rng = np.random.default_rng(seed)
    knots_t = [0, 1, 3, 3.5, 5, 6.5, 8, 8.5, 10, 11.5, 12.5, 13, 14, 16]
    knots_v = [0, 0, 5000, 5000, 0, 0, -4000, -4000, 0, 0, 3000, 3000, 0, 0]
    t_log = np.arange(-1.0, 17.0, 0.002)
    enc = np.round(np.interp(t_log, knots_t, knots_v))
    log = make_encoder_log(
        {"enc_yaw": (t_log, enc), "enc_pitch": (t_log, np.zeros_like(enc))}, None, "test", 1.0
    )
    t_cam = 0.01 + np.arange(int(15.5 * 30)) / 30.0  # camera clock = controller clock
    theta = 0.006 * np.interp(t_cam, t_log, enc) + rng.normal(0, 0.1, t_cam.size)
    theta[rng.choice(t_cam.size, 25, replace=False)] = np.nan  # tracking lost a few frames
    return log, t_cam, theta


def test_model_blocks_keep_the_whole_history_in_time_order():
    """Every block of an axis is ONE run of the axis's frames in time order (truncated
    at the ends only, unmeasured frames kept); the input is max(+-enc, 0) over all of
    them and the loss holds exactly the direction's measured frames."""
    log, t_cam, theta = _signed_session()
    series = [AxisSeries("yaw", "enc_yaw", t_cam, theta)]
    margin = 0.3
    blocks = model_blocks(series, log, 0.0, 7.0, margin, FitConfig(), 50.0)
    assert [b.name for b in blocks] == ["yaw+", "yaw-"]
    lo, hi = log.time_range()
    inside = (t_cam - margin >= lo) & (t_cam + margin <= hi)
    first, last = np.flatnonzero(inside)[[0, -1]]
    frames = t_cam[first : last + 1]
    enc = log.interpolate("enc_yaw", frames)
    direction = direction_of_samples(enc, input_bands(enc).zero_band)
    assert set(np.unique(direction)) == {-1, 1}  # every frame belongs to a direction
    profile = OffsetProfile(blocks, log, 7.0, 0.0, "gpi", FitConfig())
    rest = long_rest(frames, enc, input_bands(enc).zero_band)
    for b, sign in zip(blocks, (1, -1), strict=True):
        np.testing.assert_array_equal(b.t_cam_s, frames)  # no frame dropped, none reordered
        assert np.all(np.diff(b.t_cam_s) > 0)
        np.testing.assert_array_equal(b.in_direction, direction == sign)
        mine = (direction == sign) & ~rest
        want = np.where(mine, sign * theta[first : last + 1], np.nan)
        # NaN: other direction, unmeasured, or a long rest at zero
        np.testing.assert_array_equal(b.theta_deg, want)
        v = profile.inputs(b, 0.0)
        np.testing.assert_allclose(v, np.maximum(sign * enc, 0.0))
        # the input rests at 0 (no jump) through the other direction's excursion
        assert np.all(v[direction == -sign] <= input_bands(enc).zero_band)
        # no fake step: never a larger frame-to-frame change than the recorded input's
        assert np.max(np.abs(np.diff(v))) <= np.max(np.abs(np.diff(enc))) + 1e-9
    # the loss masks partition the measured frames, less the long rests at zero
    loss = np.isfinite(blocks[0].theta_deg) | np.isfinite(blocks[1].theta_deg)
    np.testing.assert_array_equal(loss, np.isfinite(theta[first : last + 1]) & ~rest)
    # a rest keeps its first REST_KEEP_S (the corner where the input stops), then leaves
    # the loss; the 1.5 s holds at zero here lose about 1 s each
    in_band = np.abs(enc) <= input_bands(enc).zero_band
    assert 0 < rest.sum() < in_band.sum()
    assert np.all(~rest[frames - frames[0] <= REST_KEEP_S])


def test_model_blocks_follow_the_offset_and_truncate_only_the_ends():
    log, t_cam, theta = _signed_session(1)
    series = [AxisSeries("yaw", "enc_yaw", t_cam, theta)]
    # split forced: at these offsets the frames start inside an excursion, which by
    # itself makes the default choice the signed model (as `fit` would choose)
    for offset in (-0.8, 0.0, 0.9):
        (b_plus, _) = model_blocks(series, log, offset, 7.0, 0.1, FitConfig(split=True), 50.0)
        tc = map_times(b_plus.t_cam_s, offset, 0.0, 7.0)
        lo, hi = log.time_range()
        assert tc[0] - 0.1 >= lo and tc[-1] + 0.1 <= hi
        i0 = int(np.searchsorted(t_cam, b_plus.t_cam_s[0]))
        np.testing.assert_array_equal(b_plus.t_cam_s, t_cam[i0 : i0 + b_plus.t_cam_s.size])


@pytest.mark.parametrize("rho", [0.0, 0.6, 0.9])
def test_newey_west_inflation_matches_ar1(rho):
    """For AR(1) scores the long-run variance / white variance is (1 + rho)/(1 - rho);
    the data-driven Bartlett lag recovers it to the sampling error of 3 seeds x 20k."""
    want = (1 + rho) / (1 - rho)
    got = []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        e = rng.normal(size=20000)
        s = np.empty_like(e)
        s[0] = e[0]
        for i in range(1, e.size):
            s[i] = rho * s[i - 1] + e[i]
        lag = nw_bandwidth([s])
        got.append(long_run_covariance([s], lag)[0, 0] / float(s @ s))
    # Bartlett bias ~ want/L and sd ~ want*sqrt(4L/3n): 15 % covers both for rho <= 0.9
    assert np.mean(got) == pytest.approx(want, rel=0.15)


def _block_bias_case(rng, tau_s: float, sd_s: float, sequential: bool):
    """Per-cycle offsets of two blocks (4 cycles each) with a shared bias per block.

    ``sequential``: block 0 in the first half, block 1 in the second (yaw then pitch);
    else both blocks' cycles interleaved over the whole recording (yaw+ and yaw-).
    Truth: offset 0 at t_c = 30 s, drift 40 ppm.
    """
    if sequential:
        t = np.concatenate([np.linspace(3, 27, 4), np.linspace(33, 57, 4)])
    else:
        t = np.concatenate([np.linspace(3, 51, 4), np.linspace(9, 57, 4)])
    blk = np.repeat([0, 1], 4)
    u = rng.normal(0.0, tau_s, 2)
    o = 40e-6 * (t - 30.0) + u[blk] + rng.normal(0.0, sd_s, t.size)
    return t, o, np.full(t.size, sd_s), blk


@pytest.mark.parametrize("sequential", [True, False])
def test_block_bias_sd_covers_a_shared_misfit(sequential):
    """A bias shared by all cycles of a block (as large as the cycle scatter): the truth
    lies inside 3 stated sd for offset and drift in >= 97 % of 400 draws, where the
    white line through the cycles (what the drift sd was before) is overconfident when
    the blocks move one after the other."""
    rng = np.random.default_rng(3)
    z_new, z_old = [], []
    for _ in range(400):
        t, o, sd, blk = _block_bias_case(rng, 1e-3, 1e-3, sequential)
        x = np.column_stack([np.ones(t.size), (t - 30.0) * 1e-6])
        (o_c, d), *_ = np.linalg.lstsq(x, o, rcond=None)  # the clock, as Gauss-Newton fits it
        cov, info = block_bias_cov(t, o, sd, blk, 30.0, o_c, d)
        z_new.append([o_c / np.sqrt(cov[0, 0]), (d - 40.0) / np.sqrt(cov[1, 1])])
        _, _, cov_line, _ = clock_from_offsets(t, o, sd, True, "if_larger")
        z_old.append((d - 40.0) / np.sqrt(cov_line[1, 1]))
        assert info["n_blocks"] == 2 and info["tau_s"] > 0
    cover = np.mean(np.abs(np.array(z_new)) <= 3.0, axis=0)
    assert (cover >= 0.97).all(), cover
    old = np.mean(np.abs(np.array(z_old)) <= 3.0)
    if sequential:
        assert old < 0.95, old  # the plain line misses the shared bias (0.93 here)
