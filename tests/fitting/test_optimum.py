"""A fixed-seed subset of ``benchmarks/bench_optimum.py``: every fit ends at or below its
truth's cost (x 1.001) on in-family data.

The cases are the benchmark's own (kind, seed) draws: for each kind and protocol the
first seed drawn at 5 Hz with at most 700 samples, and for the fast kinds (gpi, agpi,
bouc_wen, maxwell_slip) the first 500 Hz case from rest with at most 5000 samples;
chosen by that rule, not by their outcome. Reproduce one with
``python benchmarks/bench_optimum.py --case KIND:SEED``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))

import bench_optimum  # noqa: E402

#: Kinds whose case runs in a fresh process, as ``i2ris-calib fit`` does: the coupled
#: model's search is sensitive to the last bits of its costs, which in one long-lived
#: process depend on what ran before it (issue 31, "results depend on process
#: history": agpi_coupled:2 ended at 1348x its truth's cost once inside the whole suite,
#: and at 1.0x alone). A fresh process tests what a user runs.
FRESH_PROCESS_KINDS = ("agpi_coupled",)


def run_case(kind: str, seed: int) -> dict:
    """:func:`bench_optimum.run_case`, in a fresh process for :data:`FRESH_PROCESS_KINDS`."""
    if kind not in FRESH_PROCESS_KINDS:
        return bench_optimum.run_case(kind, seed)
    import json
    import subprocess

    code = (
        "import json, sys; sys.path.insert(0, sys.argv[1]); import bench_optimum; "
        "r = bench_optimum.run_case(sys.argv[2], int(sys.argv[3])); "
        "print(json.dumps({k: (v if isinstance(v, (str, int, float, bool, type(None))) "
        "else str(v)) for k, v in r.items()}))"
    )
    bench = str(Path(__file__).parents[2] / "benchmarks")
    out = subprocess.run([sys.executable, "-c", code, bench, kind, str(seed)],
                         capture_output=True, text=True, check=True)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


#: (kind, seed, protocol the seed draws)
CASES = [
    ("gpi", 8, "paper"),
    ("gpi", 6, "paper_mid"),
    ("gpi", 10, "circles_mid"),
    ("gpi", 18, "paper"),  # 500 Hz
    ("egpi", 1, "paper"),
    ("egpi", 4, "paper_mid"),
    ("egpi_c", 5, "paper"),
    # ~14 s: slow since the default run reached its 5-minute budget (egpi_c on the
    # default run: egpi_c:5 here; egpi paper_mid: egpi:4)
    pytest.param("egpi_c", 1, "paper_mid", marks=pytest.mark.slow),
    ("agpi", 25, "ramps"),
    ("agpi", 39, "circles"),
    ("agpi", 2, "circles_mid"),
    ("agpi", 5, "ramps"),  # 500 Hz
    ("agpi_coupled", 14, "circles"),
    ("agpi_coupled", 2, "circles_mid"),
    ("bouc_wen", 18, "ramps"),
    ("bouc_wen", 17, "circles"),
    ("bouc_wen", 0, "circles_mid"),
    ("bouc_wen", 7, "ramps"),  # 500 Hz
    ("maxwell_slip", 1, "ramps"),
    ("maxwell_slip", 0, "circles"),
    ("maxwell_slip", 9, "circles_mid"),
    ("maxwell_slip", 29, "ramps"),  # 500 Hz
]


def test_subset_covers_every_kind_and_protocol():
    covered = {(k, p) for k, _, p in (getattr(c, "values", c) for c in CASES)}
    wanted = {(k, p) for k, ps in bench_optimum.PROTOCOLS.items() for p in ps}
    assert covered == wanted


def case_ids(cases) -> list[str]:
    """``kind:seed`` of each case, a (kind, seed, protocol) tuple or its pytest.param."""
    return [":".join(map(str, getattr(c, "values", c)[:2])) for c in cases]


@pytest.mark.parametrize("kind, seed, protocol", CASES, ids=case_ids(CASES))
def test_fit_ends_at_or_below_the_truths_cost(kind, seed, protocol):
    r = run_case(kind, seed)
    assert r["protocol"] == protocol, "the benchmark's draws changed: pick the seeds again"
    assert not r["error"], f"{kind}:{seed}: the fit raised {r['error']}"
    assert r["chisqr_mismatch"] < 1e-9, "FitResult.chisqr is not the cost of its predict()"
    what = (
        f"{kind}:{seed} ({r['protocol']}, {r['rate_hz']:g} Hz, n={r['n']}, noise "
        f"{r['noise_deg']:.3g} deg)"
    )
    extra = ""
    if r["level_cost"] == r["level_cost"]:  # a mid-loop case: not NaN
        extra = (
            f"; the truth's values with the fitter's one-level start state cost "
            f"{r['level_cost']:.6g} (fit / that {r['level_ratio']:.5g})"
        )
    assert r["ratio"] <= bench_optimum.TOLERANCE, (
        f"{what}: fit cost {r['fit_cost']:.6g} > {bench_optimum.TOLERANCE} x truth cost "
        f"{r['truth_cost']:.6g} (ratio {r['ratio']:.5g}){extra}; reproduce: "
        f"python benchmarks/bench_optimum.py --case {kind}:{seed}"
    )


#: Mid-loop starts after loops of varying amplitude (issue 31): the operators' state at
#: the first sample is a staircase of three turning points (a loop, a smaller one inside
#: it), beyond the two-level pre-history, or one the level profiles alone stopped short
#: of. Each failed before the third level and the end-of-search level sweeps (fit /
#: truth cost 1.027, 1.63, 1.11, 1.098, 1.196; misses of the 40-case run).
_SLOW = pytest.mark.slow  # the coupled cases: ~8 s each; run with -m slow
STAIRCASE_CASES = [
    ("agpi", 16, "circles_mid"),  # 5 Hz, n=564
    ("maxwell_slip", 4, "circles_mid"),  # 500 Hz, n=6045
    # ~20 s (slow); coupled mid-loop on the default run: agpi_coupled:2 in CASES
    pytest.param("agpi_coupled", 19, "circles_mid", marks=_SLOW),  # 5 Hz, n=379
    pytest.param("agpi_coupled", 23, "circles_mid", marks=_SLOW),  # 5 Hz, n=1280
    pytest.param("agpi_coupled", 33, "circles_mid", marks=_SLOW),  # 5 Hz, n=819: other motor
    # the other motor's state: a loop's two extremes and the turn of its current
    # excursion (three levels), held through this motor's replayed cycle, started from
    # a grid over two of them (fit / truth cost 1.62 before)
    pytest.param("agpi_coupled", 29, "circles_mid", marks=_SLOW),  # 5 Hz, n=825
    # a whole staircase searched at the end (fit._staircases): each missed before with its
    # history's state within the three levels (fit / truth cost 5.91, 1.035, 1.024,
    # 1.146; agpi_coupled:166, a miss of the 200-case run before, 0.929 after)
    ("maxwell_slip", 170, "circles_mid"),  # 5 Hz, n=303
    ("agpi", 149, "circles_mid"),  # 500 Hz, n=3129
    pytest.param("maxwell_slip", 103, "circles_mid", marks=_SLOW),  # 5 Hz, n=1068
    pytest.param("maxwell_slip", 146, "circles_mid", marks=_SLOW),  # 500 Hz, n=13,387
    pytest.param("agpi_coupled", 166, "circles_mid", marks=_SLOW),  # 5 Hz, n=656
    # the start state's re-search on every recording up to fit.LARGE_ROWS samples, not
    # only where a polish is cheap: a 500 Hz two-motor recording (1.338x before, ~55 s)
    pytest.param("agpi_coupled", 69, "circles_mid", marks=_SLOW),  # 500 Hz, n=19,509
    # the grid's staircases short-run by LM as found, not only refined with the
    # parameters held (fit._best_staircases; fit / truth cost 1.046 before)
    ("maxwell_slip", 95, "circles_mid"),  # 5 Hz, n=540
    # histories of four turning points: a fourth own level on a recording of up to
    # fit.FOUR_LEVEL_ROWS samples (fit / truth cost 1.353 and 1.026 with three)
    ("maxwell_slip", 67, "circles_mid"),  # 5 Hz, n=457
    pytest.param("maxwell_slip", 65, "circles_mid", marks=_SLOW),  # 500 Hz, n=3,123
]


@pytest.mark.parametrize(
    "kind, seed, protocol",
    STAIRCASE_CASES,
    ids=case_ids(STAIRCASE_CASES),
)
def test_staircase_start_state_reaches_the_truths_cost(kind, seed, protocol):
    test_fit_ends_at_or_below_the_truths_cost(kind, seed, protocol)


#: Mid-loop coupled cases whose coupling starts, made from the base fit's residual from
#: rest, fitted its start-state error (issue 31): each failed before the starts from
#: the residual without it (``pipeline.rested_angle``; fit / truth cost 1.018 in a
#: fresh process).
RESTED_CASES = [
    pytest.param("agpi_coupled", 31, "circles_mid", marks=_SLOW),  # 500 Hz, n=3799
]


@pytest.mark.parametrize("kind, seed, protocol", RESTED_CASES, ids=["agpi_coupled:31"])
def test_coupling_starts_without_the_base_start_state_reach_the_truths_cost(kind, seed, protocol):
    test_fit_ends_at_or_below_the_truths_cost(kind, seed, protocol)


#: A mid-loop coupled case whose other motor turned a few samples before the recording
#: (issue 31): every start's other motor arrived at its first value from the far side of
#: its last loop, the reversal 19 counts back beyond the level grids' spacing (361); now
#: the last level is also profiled close to the first input and the grid's loop is tried
#: one turning point back (fit.py ``_near_first``, ``_pair_grid``). Fit / truth cost
#: before: 1.0010 (0.998 after).
LAST_REVERSAL_CASES = [
    pytest.param("agpi_coupled", 7, "circles_mid", marks=_SLOW),  # 500 Hz, n=16,598
]


@pytest.mark.parametrize("kind, seed, protocol", LAST_REVERSAL_CASES, ids=["agpi_coupled:7"])
def test_last_reversal_before_the_recording_reaches_the_truths_cost(kind, seed, protocol):
    test_fit_ends_at_or_below_the_truths_cost(kind, seed, protocol)


#: EGPI flag-point basins (issue 31): every data-driven start's screened end stayed at
#: its own flag-point estimate, far from the best end's, so no start tried its shape
#: where the flag point belongs; now screened again at the best end's flag point
#: (fit.py ``_flag_point_carried``). Fit / truth cost before: 1.109. egpi:153: the
#: flag-point estimate from every long unloading stretch, two of them turned below the
#: flag point (1,745, the truth's 2,107); now from those that come down from the top of
#: the range (start.py ``flag_point``). Before: 9.80. egpi_c:4: a noisy bin just below
#: the top of both full-scale unloading stretches read flat between neighbouring bins
#: (4,916, the truth's 3,558); now the slope is read over three bins (start.py
#: ``flag_point``: 3,619) for one more start. Before: 1.082 (0.9991 after). egpi:49,
#: egpi:63 and egpi:100: the three-bin reading as the first start put them in a worse
#: basin (3.42, 8.79 and 2.77, though closer to the truth's flag point); the neighbouring-bin
#: reading stays the first start (start.py ``flag_point_candidates``).
FLAG_POINT_CASES = [
    ("egpi", 5, "paper"),  # 5 Hz, n=640: starts at v_f 3,923, the truth's 3,003
    ("egpi", 153, "paper"),  # 5 Hz, n=489: starts at v_f 1,745, the truth's 2,107
    # ~15 s of fitting (slow): 500 Hz, n=19,243, noise 0.45 deg
    pytest.param("egpi_c", 4, "paper", marks=_SLOW),
    ("egpi", 63, "paper_mid"),  # 5 Hz, n=663, ~5 s: 8.79 from the three-bin reading alone
    pytest.param("egpi", 49, "paper_mid", marks=_SLOW),  # 5 Hz, n=305: 3.42 from it alone
    # ~6 s (slow, the default run's 5-minute budget): egpi:63 above keeps the hazard
    pytest.param("egpi", 100, "paper_mid", marks=_SLOW),  # 5 Hz, n=433: 2.77 three-bin first
]


@pytest.mark.parametrize(
    "kind, seed, protocol",
    FLAG_POINT_CASES,
    ids=case_ids(FLAG_POINT_CASES),
)
def test_flag_point_basin_reaches_the_truths_cost(kind, seed, protocol):
    test_fit_ends_at_or_below_the_truths_cost(kind, seed, protocol)


#: A short coupled recording from rest whose coupling is a large share of the angle
#: (issue 31): the two-tendon GPI fitted without the other motor's input (the base)
#: ended in a degenerate basin (sigma 0, r1 = rn) that every coupled start carried,
#: all ~17,500 in cost; now the joint starts (both motors' slopes at once, the own
#: tendons from the angle less the coupling's straight-line part: ~1,000) reach the
#: truth's basin (``coupled.coupled_starts``, ``pipeline.JOINT_ROWS``). Fit / truth
#: cost before: 36,756 (0.87 after). Cheap (~1 s of fitting): on the default run.
#: agpi_coupled:121 (500 Hz, 5,750 fitted samples, beyond ``JOINT_ROWS``): the joint
#: starts in a second search of their own (``pipeline._joint_search``). Before: 2216x
#: (0.9965 after); ~30 s of fitting: slow.
JOINT_START_CASES = [
    ("agpi_coupled", 112, "circles"),  # 5 Hz, n=362
    pytest.param("agpi_coupled", 121, "circles_mid", marks=_SLOW),
]


@pytest.mark.parametrize(
    "kind, seed, protocol",
    JOINT_START_CASES,
    ids=case_ids(JOINT_START_CASES),
)
def test_joint_coupling_starts_reach_the_truths_cost(kind, seed, protocol):
    test_fit_ends_at_or_below_the_truths_cost(kind, seed, protocol)
