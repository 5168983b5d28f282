"""Online Compensator speed (issue 21 item 5): median microseconds per ``step()`` on one
core, and the batch ``compensate()`` time for 1e6 samples.

    NUMBA_NUM_THREADS=1 python benchmarks/bench_compensator_step.py [--kinds gpi egpi ...]

Model: the paper-like yaw+ preset (agpi: a two-tendon preset), whole counts, rate limit
5000 counts/s, a smooth 100 Hz target (15 + 8 sin(0.7 t) + 3 sin(2.1 t) deg). Targets:
<= 20 us per step, <= 5 s per 1e6 batch samples.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from i2ris_calib.compensation import compensate
from i2ris_calib.compensation.online import Compensator
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.hysteresis.presets import gpi_values, paper_like_params
from i2ris_calib.hysteresis.registry import model_for_kind

AGPI = dict(
    theta0=0.4, a1_p=0.008, a3_p=0.0072, a4_p=-1.2, lam_p=0.06, sigma_p=0.25, r1_p=0.3,
    rn_p=3.5, a1_n=0.0065, a3_n=0.006, a4_n=-0.8, lam_n=0.06, sigma_n=0.2, r1_n=0.4, rn_n=3.0,
)  # fmt: skip


def setup(kind: str, n: int):
    t = np.arange(n) * 0.01
    wave = 8 * np.sin(0.7 * t) + 3 * np.sin(2.1 * t)
    if kind == "agpi":
        return model_for_kind("agpi", **AGPI), (-4000.0, 4000.0), wave, t
    pp = paper_like_params("yaw+")
    model = model_from_params(kind, gpi_values(pp) if kind == "gpi" else pp, 30, 2.0)
    return model, (0.0, 6000.0), 15 + wave, t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", nargs="+", default=["gpi", "egpi", "egpi_c", "agpi"])
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--batch", type=int, default=1_000_000)
    args = ap.parse_args()
    for kind in args.kinds:
        model, lim, target, t = setup(kind, args.steps)
        c = Compensator({"yaw": model}, {"yaw": lim}, max_counts_per_s=5000.0)
        for x in target[:100]:  # compile, warm
            c.step(float(x), dt_s=0.01)
        c.reset()
        per = np.empty(target.size)
        clock = time.perf_counter
        for k, x in enumerate(target.tolist()):
            t0 = clock()
            c.step(x, dt_s=0.01)
            per[k] = clock() - t0
        med = 1e6 * float(np.median(per))
        model, lim, target, t = setup(kind, args.batch)
        compensate(model, target[:1000], t[:1000], v_limits=lim, max_rate=5000.0, v_initial=0.0)
        t0 = time.perf_counter()
        compensate(model, target, t, v_limits=lim, max_rate=5000.0, v_initial=0.0)
        batch = time.perf_counter() - t0
        print(
            f"{kind:7s} step(): median {med:6.2f} us (p99 {1e6 * np.percentile(per, 99):6.2f} us,"
            f" {'PASS' if med <= 20 else 'FAIL'} <= 20); batch {args.batch:.0e} samples: "
            f"{batch:5.2f} s ({'PASS' if batch <= 5 else 'FAIL'} <= 5)"
        )


if __name__ == "__main__":
    main()
