"""Benchmark of the diagnosis: is the hidden effect named, and only it?

Default suite: ``tests/diagnosis/independent_cases.py``, generators written
without the catalogue (a classical Prandtl-Ishlinskii base in its own
parametrisation, each effect from its textbook definition, ramps of 2-10 s with
holds): 12 effects x 2 strengths x 2 draws (noise 0.08 and 0.2 deg) + 8 clean
cases, diagnosed with ``--start auto`` (from GPI and from EGPI, reconciled).
Prints the confusion table (hidden effect x first named effect) and:

- right effect named first, over all hidden-effect cases, and (target >= 90 %) over
  those left after setting apart the cases where nothing was named and the answer
  lists the hidden effect as not excluded (the data cannot tell it from the start
  model: e.g. a backlash the base's envelope offsets absorb exactly);
- nothing named, over clean cases (target >= 95 %);
- held-out RMSE shrink (1 - final/baseline) >= 50 % in >= 80 % of the cases whose
  effect (RMS of what it adds to the angle) exceeds twice the noise;
- the same figures per effect;
- wall and CPU time of a diagnosis of 10k samples (target <= 30 s on 2 cores).

Usage::

    python benchmarks/bench_diagnosis.py              # 56 cases + the 10k timing
    python benchmarks/bench_diagnosis.py -j 2         # two worker processes
    python benchmarks/bench_diagnosis.py --quick      # 12 hidden + 2 clean cases
    python benchmarks/bench_diagnosis.py --only-timing
    python benchmarks/bench_diagnosis.py --approximation   # additive vs proportional thresholds
    python benchmarks/bench_diagnosis.py --power -j 2      # power-form thresholds, 4 cases
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "diagnosis"))

from independent_cases import (  # noqa: E402
    SUITE,
    case_as_dataset,
    expected_name,
    make_independent_case,
    suite,
)

from i2ris_calib.diagnosis.config import DiagnosisConfig  # noqa: E402
from i2ris_calib.diagnosis.workflow import diagnose_from_starts  # noqa: E402
from i2ris_calib.hysteresis.effects import CATALOGUE  # noqa: E402


def run_independent(args) -> dict:
    """Diagnose one independent case (``args`` = effect, strength, noise, seed, starts)."""
    effect, strength, noise, seed, starts = args
    case = make_independent_case(seed, effect, strength, noise)
    data = case_as_dataset(case)
    t0, c0 = time.perf_counter(), time.process_time()
    auto = diagnose_from_starts(data, DiagnosisConfig(), starts=starts)
    dt, dc = time.perf_counter() - t0, time.process_time() - c0
    diag = auto.diagnosis
    named = diag.named_effects
    alts = [a for s in diag.steps[:1] for a in s.alternatives if not a.excluded]
    # what the answer says it cannot tell from its final model (nothing more named),
    # over both paths (AutoDiagnosis.not_excluded: the union)
    open_ = [(a.effect, round(a.z, 1), round(a.effect_rms_deg, 2), k) for k, a in auto.not_excluded]
    return {
        "effect": effect or "clean",
        "expected": expected_name(effect) if effect else "none",
        "strength": strength,
        "noise_deg": noise,
        "effect_rms_deg": case.effect_rms_deg,
        "named": named,
        "first": named[0] if named else "none",
        "start": auto.start,
        "paths": {k: p.named_effects for k, p in auto.paths.items()},
        "alternatives": [(a.effect, round(a.z, 1)) for a in alts],
        "not_excluded": open_,
        "baseline_holdout_deg": diag.baseline.holdout_rmse_deg,
        "final_holdout_deg": diag.final.holdout_rmse_deg,
        "shrink": 1.0 - diag.final.holdout_rmse_deg / diag.baseline.holdout_rmse_deg,
        "seconds": dt,
        "cpu_seconds": dc,
    }


def _effects(rows: list[dict]) -> list[str]:
    """The suite's effects, then any other generated effect in ``rows``."""
    extra = [r["effect"] for r in rows if r["effect"] not in SUITE and r["effect"] != "clean"]
    return [*SUITE, *dict.fromkeys(extra)]


def confusion(rows: list[dict]) -> str:
    """Text table: hidden effect (rows) x first named effect (columns)."""
    cols = [*CATALOGUE, "none"]
    abbrev = {"rate_dependent_thresholds": "rd_thresh", "rate_dependent_weights": "rd_weight"}
    short = {c: abbrev.get(c, c[:9]) for c in cols}
    head = f"{'hidden | named first':<33}" + "".join(f"{short[c]:>10}" for c in cols)
    lines = [head]
    for hidden in [*_effects(rows), "clean"]:
        sel = [r for r in rows if r["effect"] == hidden]
        if not sel:
            continue
        counts = [sum(r["first"] == c for r in sel) for c in cols]
        lines.append(f"{hidden:<33}" + "".join(f"{n:>10}" for n in counts))
    return "\n".join(lines)


def _not_identified(r: dict) -> bool:
    """Nothing named, and the answer lists the hidden effect as not excluded."""
    return r["first"] == "none" and r["expected"] in [a[0] for a in r.get("not_excluded", [])]


def _left(r: dict) -> float:
    """Systematic held-out error the starting model leaves, sqrt(RMSE^2 - noise^2) (deg)."""
    return float(np.sqrt(max(r["baseline_holdout_deg"] ** 2 - r["noise_deg"] ** 2, 0.0)))


def summary(rows: list[dict]) -> list[str]:
    """Print the target figures and the per-effect figures; returns the missed targets
    (right first >= 90 % of the cases not set apart, nothing named on >= 95 % of the
    clean ones, held-out shrink >= 50 % on >= 80 % of those the start leaves > 2x noise)."""
    missed = []
    hidden = [r for r in rows if r["effect"] != "clean"]
    clean = [r for r in rows if r["effect"] == "clean"]
    print()
    print(confusion(rows))
    print()
    if hidden:
        right = sum(r["first"] == r["expected"] for r in hidden)
        only = sum(r["named"] == [r["expected"]] for r in hidden)
        tied = [r for r in hidden if _not_identified(r)]
        ident = [r for r in hidden if not _not_identified(r)]
        right_i = sum(r["first"] == r["expected"] for r in ident)
        wrong = sum(r["first"] not in (r["expected"], "none") for r in hidden)
        print(
            f"right effect named first : {right}/{len(hidden)} = "
            f"{100 * right / len(hidden):.1f}% of all hidden-effect cases"
        )
        print(
            f"  reported apart          : {len(tied)} cases where nothing was named and the "
            "answer lists the hidden effect as not excluded (the data cannot tell it from the "
            "start model)"
        )
        if ident:
            print(
                f"  right first, the rest   : {right_i}/{len(ident)} = "
                f"{100 * right_i / len(ident):.1f}% (target >= 90%)"
            )
            if right_i < 0.9 * len(ident):
                missed.append(f"right first {right_i}/{len(ident)} < 90 %")
        print(f"wrong effect named first : {wrong}/{len(hidden)}")
        print(f"exactly the right effect : {only}/{len(hidden)} = {100 * only / len(hidden):.1f}%")
    if clean:
        none = sum(not r["named"] for r in clean)
        print(
            f"clean: nothing named     : {none}/{len(clean)} = "
            f"{100 * none / len(clean):.1f}% (target >= 95%)"
        )
        if none < 0.95 * len(clean):
            missed.append(f"clean nothing named {none}/{len(clean)} < 95 %")
    for label, big in (
        ("effect RMS > 2x noise", [r for r in hidden if r["effect_rms_deg"] > 2 * r["noise_deg"]]),
        ("start leaves > 2x noise", [r for r in hidden if _left(r) > 2 * r["noise_deg"]]),
    ):
        if big:
            ok = sum(r["shrink"] >= 0.5 for r in big)
            shr = np.array([r["shrink"] for r in big])
            print(
                f"shrink >= 50% ({label}): {ok}/{len(big)} = {100 * ok / len(big):.1f}% "
                f"(target >= 80%); median shrink {100 * np.median(shr):.0f}%"
            )
            if label.startswith("start") and ok < 0.8 * len(big):
                missed.append(f"shrink >= 50 % ({label}) {ok}/{len(big)} < 80 %")
    found = [r for r in hidden if _left(r) > 2 * r["noise_deg"]]
    if found:
        right = sum(r["first"] == r["expected"] for r in found)
        print(
            f"right first where the start leaves > 2x noise: {right}/{len(found)} = "
            f"{100 * right / len(found):.1f}%"
        )
    print()
    print(
        f"{'effect':<33}{'first right':>12}{'not excl.':>11}{'shrink>=50%':>13}"
        f"{'median shrink':>15}"
    )
    for name in _effects(rows):
        sel = [r for r in hidden if r["effect"] == name]
        if not sel:
            continue
        b = [r for r in sel if r["effect_rms_deg"] > 2 * r["noise_deg"]]
        print(
            f"{name:<33}{sum(r['first'] == r['expected'] for r in sel):>6}/{len(sel):<5}"
            f"{sum(_not_identified(r) for r in sel):>7}/{len(sel):<3}"
            f"{sum(r['shrink'] >= 0.5 for r in b):>7}/{len(b):<5}"
            f"{100 * np.median([r['shrink'] for r in sel]):>14.0f}%"
        )
    for r in rows:
        if r["effect"] == "clean" and r.get("not_excluded"):
            print(f"clean case (noise {r['noise_deg']}): not excluded {r['not_excluded']}")
    secs = np.array([r["seconds"] for r in rows])
    cpu = np.array([r["cpu_seconds"] for r in rows])
    n = rows[0].get("n_samples", "")
    print(
        f"\ntime per case (both start fits + both diagnoses{', ' + str(n) if n else ''}): "
        f"wall median {np.median(secs):.1f} s, max {secs.max():.1f} s; "
        f"CPU median {np.median(cpu):.1f} s, max {cpu.max():.1f} s"
    )
    return missed


def timing_10k(starts) -> list[str]:
    """Wall and CPU time of one ``--start auto`` diagnosis of ~10k samples; returns the
    missed target (CPU <= 30 s), if any."""
    case = make_independent_case(4242, "backlash", 0.05, 0.1, n_moves=40)
    data = case_as_dataset(case)
    t0, c0 = time.perf_counter(), time.process_time()
    auto = diagnose_from_starts(data, DiagnosisConfig(), starts=starts)
    dt, dc = time.perf_counter() - t0, time.process_time() - c0
    print(
        f"10k timing: {data.n_samples} samples, starts {'+'.join(starts)}, named "
        f"{auto.diagnosis.named_effects}: wall {dt:.1f} s, CPU {dc:.1f} s "
        f"(target <= 30 s on 2 cores)"
    )
    return [f"10k diagnosis CPU {dc:.1f} s > 30 s"] if dc > 30.0 else []


def approximation_rdt(noise: float = 0.01) -> None:
    """How well ``rate_dependent_thresholds`` (a common widening ``beta |v'|``) fits
    thresholds that widen in proportion, ``r_i (1 + beta |v'|)``: the suite's draws of
    that generator at low noise, GPI start, only that candidate, one step; prints the
    systematic held-out error ``sqrt(RMSE^2 - noise^2)`` before and after."""
    cfg = DiagnosisConfig(candidates=["rate_dependent_thresholds"], max_steps=1)
    name = "rate_dependent_thresholds_scaled"
    seeds = [seed for e, _, _, seed in suite() if e == name]
    for s in SUITE[name]:
        for seed in seeds:
            case = make_independent_case(seed, name, s, noise)
            d = diagnose_from_starts(case_as_dataset(case), cfg, starts=("gpi",)).diagnosis

            def left(r):
                return float(np.sqrt(max(r**2 - noise**2, 0.0)))

            print(
                f"{name} s={s} seed {seed}: effect RMS {case.effect_rms_deg:.3f} deg, named "
                f"{d.named_effects}, systematic held-out error "
                f"{left(d.baseline.holdout_rmse_deg):.3f} -> {left(d.final.holdout_rmse_deg):.3f}"
                f" deg ({100 * left(d.final.holdout_rmse_deg) / case.effect_rms_deg:.0f}% of "
                "the effect RMS)",
                flush=True,
            )


#: (strength k, noise, seed) of the power-form cases (``--power``; not in the suite).
POWER_CASES = [(1.0, 0.08, 8101), (1.0, 0.2, 8102), (2.0, 0.08, 8103), (2.0, 0.2, 8104)]


def main() -> int:
    """Run the benchmark; 1 when a target is missed (``--power``/``--approximation``
    have no target)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="strong strength, one draw")
    ap.add_argument("-j", type=int, default=1, help="worker processes")
    ap.add_argument("--start", default="auto", choices=("auto", "gpi", "egpi"))
    ap.add_argument("--only-timing", action="store_true")
    ap.add_argument(
        "--power",
        action="store_true",
        help="only: 4 cases of power-form thresholds r_i k (|v'|/max)^0.5 (not in the suite)",
    )
    ap.add_argument(
        "--approximation",
        action="store_true",
        help="only: how rate_dependent_thresholds fits proportional thresholds (noise 0.01)",
    )
    ap.add_argument("--effects", default="", help="comma-separated subset of effects")
    ap.add_argument("--json", default="", help="also write the rows to this JSON file")
    args = ap.parse_args()
    starts = ("gpi", "egpi") if args.start == "auto" else (args.start,)
    if args.approximation:
        approximation_rdt()
        return 0
    if args.power:
        jobs = [
            ("rate_dependent_thresholds_power", k, n, seed, starts) for k, n, seed in POWER_CASES
        ]
        with ProcessPoolExecutor(max(args.j, 1)) as ex:
            rows = list(ex.map(run_independent, jobs))
        for r in rows:
            _line(r)
        summary(rows)
        return 0
    missed = []
    if not args.only_timing:
        todo = suite()
        if args.effects:
            keep = set(args.effects.split(","))
            todo = [c for c in todo if (c[0] or "clean") in keep]
        if args.quick:
            todo = [c for c in todo if c[0] is None or (c[1] == SUITE[c[0]][1] and c[2] == 0.2)]
            todo = [c for c in todo if c[0] is not None] + [c for c in todo if c[0] is None][:2]
        jobs = [(*c, starts) for c in todo]
        rows = []
        if args.j > 1:
            with ProcessPoolExecutor(args.j) as ex:
                it = ex.map(run_independent, jobs)
                for r in it:
                    rows.append(r)
                    _line(r)
        else:
            for job in jobs:
                r = run_independent(job)
                rows.append(r)
                _line(r)
        missed += summary(rows)
        if args.json:
            Path(args.json).write_text(json.dumps(rows, indent=1))
    missed += timing_10k(starts)
    print("targets: " + ("met" if not missed else "MISSED: " + "; ".join(missed)))
    return 1 if missed else 0


def _line(r: dict) -> None:
    print(
        f"{r['effect']:<27} s={r['strength']:<6g} noise {r['noise_deg']:.2f} "
        f"eff {r['effect_rms_deg']:.2f} deg  named {r['named']} (from {r['start']}; "
        f"paths {r['paths']}; alternatives {r['alternatives']}; not excluded "
        f"{r.get('not_excluded', [])})  held-out "
        f"{r['baseline_holdout_deg']:.3f} -> {r['final_holdout_deg']:.3f}  "
        f"({r['seconds']:.0f} s, cpu {r['cpu_seconds']:.0f} s)",
        flush=True,
    )


if __name__ == "__main__":
    sys.exit(main())
