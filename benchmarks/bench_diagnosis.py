"""Benchmark of the diagnosis: is the hidden effect named, and only it?

For every catalogue effect, EGPI data with the effect hidden at several strengths
and noise levels (:mod:`i2ris_calib.diagnosis.synthetic`); the diagnosis starts
from an EGPI fitted by the fitting stage (no effect). Plus clean cases (nothing
hidden). Prints the confusion table (hidden effect x first named effect) and:

- right effect named first, over hidden-effect cases (target >= 90 %);
- nothing named, over clean cases (target >= 95 %);
- held-out RMSE shrink (1 - final/baseline) when an effect is hidden (target >= 50 %
  in the median and per case);
- time per diagnosis.

``--two-directions``: every case is a signed recording whose loading cycles
alternate between positive and negative input
(:func:`~i2ris_calib.diagnosis.synthetic.make_two_direction_case`, 12 cycles), and the
``"-"`` dataset is diagnosed over the whole history (the ``"+"`` cycles only drive the
models).

Usage::

    python benchmarks/bench_diagnosis.py            # 42 hidden + 12 clean cases
    python benchmarks/bench_diagnosis.py --quick    # 7 hidden + 3 clean cases
    python benchmarks/bench_diagnosis.py --quick --two-directions
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from i2ris_calib.diagnosis.config import DiagnosisConfig  # noqa: E402
from i2ris_calib.diagnosis.effects import CATALOGUE  # noqa: E402
from i2ris_calib.diagnosis.synthetic import (  # noqa: E402
    STRENGTHS,
    case_dataset,
    make_case,
    make_two_direction_case,
)
from i2ris_calib.diagnosis.workflow import diagnose, fit_start_model  # noqa: E402


def cases(quick: bool) -> list[tuple[str | None, dict | None, float, int]]:
    """(effect, params, noise_deg, seed) of every case."""
    out = []
    seed = 100
    noises = (0.2,) if quick else (0.1, 0.3)
    for name in CATALOGUE:
        strengths = STRENGTHS[name][1:2] if quick else STRENGTHS[name]
        for p in strengths:
            for noise in noises:
                seed += 1
                out.append((name, p, noise, seed))
    n_clean = 3 if quick else 12
    for i in range(n_clean):
        out.append((None, None, (0.1, 0.2, 0.3)[i % 3], 500 + i))
    return out


def run_case(effect, params, noise, seed, config=None, two_directions=False) -> dict:
    """Diagnose one case; the row of the results table."""
    if two_directions:
        case = make_two_direction_case(seed, effect, params, noise_deg=noise)
        data = case_dataset(case, direction="-")  # the "-" dataset, whole history
    else:
        case = make_case(seed, effect, params, noise_deg=noise)
        data = case_dataset(case)  # the "+" Dataset fit and diagnose build from its CSV
    t0 = time.perf_counter()
    start = fit_start_model("egpi", data)
    diag = diagnose(start, data, config)
    dt = time.perf_counter() - t0
    named = diag.named_effects
    shrink = 1.0 - diag.final.holdout_rmse_deg / diag.baseline.holdout_rmse_deg
    # the systematic part of the held-out error, sqrt(RMSE^2 - noise^2)
    sys_b = np.sqrt(max(diag.baseline.holdout_rmse_deg**2 - noise**2, 0.0))
    sys_f = np.sqrt(max(diag.final.holdout_rmse_deg**2 - noise**2, 0.0))
    return {
        "effect": effect or "clean",
        "params": params or {},
        "noise_deg": noise,
        "named": named,
        "first": named[0] if named else "none",
        "baseline_holdout_deg": diag.baseline.holdout_rmse_deg,
        "final_holdout_deg": diag.final.holdout_rmse_deg,
        "shrink": shrink,
        "sys_shrink": 1.0 - sys_f / sys_b if sys_b > 0 else float("nan"),
        "seconds": dt,
    }


def confusion(rows: list[dict]) -> str:
    """Text table: hidden effect (rows) x first named effect (columns)."""
    cols = [*CATALOGUE, "none"]
    short = {c: c[:10] for c in cols}
    head = f"{'hidden | named first':<22}" + "".join(f"{short[c]:>11}" for c in cols)
    lines = [head]
    for hidden in [*CATALOGUE, "clean"]:
        sel = [r for r in rows if r["effect"] == hidden]
        if not sel:
            continue
        counts = [sum(r["first"] == c for r in sel) for c in cols]
        lines.append(f"{hidden:<22}" + "".join(f"{n:>11}" for n in counts))
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one strength, one noise level")
    ap.add_argument(
        "--choose-by", default="holdout", choices=("holdout", "bic"), help="[diagnose] choose_by"
    )
    ap.add_argument(
        "--two-directions",
        action="store_true",
        help="alternating +/- cycles; diagnose the '-' dataset over the whole history",
    )
    args = ap.parse_args()
    config = DiagnosisConfig(choose_by=args.choose_by)
    rows = []
    for effect, params, noise, seed in cases(args.quick):
        r = run_case(effect, params, noise, seed, config, args.two_directions)
        rows.append(r)
        print(
            f"{r['effect']:<21} {str(r['params']):<48} noise {noise:.1f}  named {r['named']}"
            f"  held-out {r['baseline_holdout_deg']:.3f} -> {r['final_holdout_deg']:.3f} deg"
            f"  ({r['seconds']:.1f} s)",
            flush=True,
        )
    hidden = [r for r in rows if r["effect"] != "clean"]
    clean = [r for r in rows if r["effect"] == "clean"]
    right = sum(r["first"] == r["effect"] for r in hidden)
    only = sum(r["named"] == [r["effect"]] for r in hidden)
    none = sum(not r["named"] for r in clean)
    shrink = np.array([r["shrink"] for r in hidden])
    sys_shrink = np.array([r["sys_shrink"] for r in hidden])
    secs = np.array([r["seconds"] for r in rows])
    print()
    print(confusion(rows))
    print()
    print(
        f"right effect named first : {right}/{len(hidden)} = {100 * right / len(hidden):.1f}% (target >= 90%)"
    )
    print(f"exactly the right effect : {only}/{len(hidden)} = {100 * only / len(hidden):.1f}%")
    print(
        f"clean: nothing named     : {none}/{len(clean)} = {100 * none / len(clean):.1f}% (target >= 95%)"
    )
    print(
        f"held-out RMSE shrink     : median {100 * np.median(shrink):.1f}%, min {100 * shrink.min():.1f}%,"
        f" cases >= 50%: {int((shrink >= 0.5).sum())}/{shrink.size} (target >= 50%)"
    )
    print(
        f"systematic part shrink   : median {100 * np.nanmedian(sys_shrink):.1f}%, min {100 * np.nanmin(sys_shrink):.1f}%,"
        f" cases >= 50%: {int((sys_shrink >= 0.5).sum())}/{sys_shrink.size}  [sqrt(RMSE^2 - noise^2)]"
    )
    for name in CATALOGUE:
        sel = [r for r in hidden if r["effect"] == name]
        if sel:
            print(
                f"  {name:<21} first right {sum(r['first'] == name for r in sel)}/{len(sel)},"
                f" shrink median {100 * np.median([r['shrink'] for r in sel]):.0f}%,"
                f" systematic {100 * np.nanmedian([r['sys_shrink'] for r in sel]):.0f}%"
            )
    print(
        f"time per case (start fit + diagnosis): median {np.median(secs):.1f} s, max {secs.max():.1f} s"
    )


if __name__ == "__main__":
    main()
