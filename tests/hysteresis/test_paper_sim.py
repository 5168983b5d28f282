"""Section 3.1 reproduced: dead zones detected from the simulated data (not hard-coded)."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pandas as pd
import pytest
from hyst_reference import triangle

from i2ris_calib.commands.paper_sim import write_paper_sim
from i2ris_calib.hysteresis.kernel import motion_direction
from i2ris_calib.hysteresis.paper import PAPER_SIM_VALUES, dead_zones, run_paper_sim


@pytest.fixture(scope="module")
def sim():
    return run_paper_sim()


def _full_branches(v):
    """Branch indices of v(t) except the first (it starts mid-way) and the last."""
    d = motion_direction(np.ascontiguousarray(v), 0.0)
    seg = np.concatenate(([0], np.cumsum(d[1:] != d[:-1])))
    return set(range(1, int(seg.max())))


def test_detector_finds_known_zones():
    """Piecewise-linear curve with two flat stretches on the way down, one on the way up."""
    v = triangle([0, 10, 0], step=0.01)
    y = np.where(np.arange(v.size) < 1000, v, np.nan)
    down = v[1000:]
    y[1000:] = np.interp(down, [0, 2, 4, 6, 8, 10], [0, 0, 3, 3, 7, 10])
    up = v[:1001]
    y[:1001] = np.interp(up, [0, 3, 10], [0, 0, 10])
    zones = dead_zones(v, y, rel_slope=0.1, min_width_frac=0.05)
    got = sorted((z.rising, round(z.v_start, 1), round(z.v_end, 1)) for z in zones)
    assert got == [(False, 2.0, 0.0), (False, 6.0, 4.0), (True, 0.0, 3.0)]


def test_gpi_components_one_dead_zone_per_branch(sim):
    full = _full_branches(sim.v)
    for y in (sim.z1, sim.z2):
        per_branch = Counter(z.branch for z in dead_zones(sim.v, y))
        assert {b: per_branch.get(b, 0) for b in full} == dict.fromkeys(full, 1)


def test_egpi_two_dead_zones_per_branch_at_flag_points(sim):
    zones = dead_zones(sim.v, sim.z)
    full = _full_branches(sim.v)
    per_branch = Counter(z.branch for z in zones)
    assert {b: per_branch.get(b, 0) for b in full} == dict.fromkeys(full, 2)
    # the second zone of each branch starts at the flag point of its direction
    for b in full:
        zb = [z for z in zones if z.branch == b]
        later = (
            max(zb, key=lambda z: z.v_start) if zb[0].rising else min(zb, key=lambda z: z.v_start)
        )
        flag = PAPER_SIM_VALUES["vf_rise1"] if later.rising else PAPER_SIM_VALUES["vf_fall1"]
        assert abs(later.v_start - flag) < 0.1, (b, later)


def test_paper_sim_files(tmp_path):
    summary = write_paper_sim(tmp_path)
    df = pd.read_csv(tmp_path / "paper_sim.csv")
    assert list(df.columns) == ["t", "v", "z1", "z2", "z"]
    assert df["t"].iloc[-1] == pytest.approx(10.0)
    np.testing.assert_allclose(
        df["v"], 8 * np.exp(-0.04 * df["t"]) * np.sin(2 * np.pi * df["t"] + np.pi / 4), atol=1e-5
    )
    for name in ("fig3c.png", "fig3d.png", "fig4.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert summary["dead_zones"]["z"]
    assert not list(tmp_path.glob(".*tmp*"))


def test_paper_sim_command_says_what_it_wrote(tmp_path, capsys):
    from i2ris_calib.cli import main

    assert main(["paper-sim", "--out", str(tmp_path / "p")]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith(f"wrote {tmp_path / 'p'} ") and "paper_sim.json" in last
