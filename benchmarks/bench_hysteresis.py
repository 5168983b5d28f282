"""Speed of one EGPI evaluation: compiled kernel vs a straightforward numpy version.

Run: ``python benchmarks/bench_hysteresis.py`` (``--quick``: 20,000 samples).

Model: the I2RIS EGPI (2 operator families = 2 stages, n = 30 -> 31 operators each),
100,000 samples of a Fig-5-like input. Targets (issue 2): <= 5 ms per evaluation on
one core, >= 100x faster than the numpy version (Python loop over time, numpy over
operators), both measured in this run. Outputs are checked to agree (1e-9 deg).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from i2ris_calib.hysteresis.kernel import play_numpy  # noqa: E402
from i2ris_calib.hysteresis.models import density, i2ris_egpi_model, thresholds  # noqa: E402
from i2ris_calib.hysteresis.presets import loading_trajectory, paper_like_params  # noqa: E402


def egpi_numpy(v: np.ndarray, x: np.ndarray, n: int, deadband: float) -> np.ndarray:
    """The I2RIS EGPI written plainly: numpy over operators, Python loop over time."""
    a1, a2, a3, a4, a5, a6, lam, sigma, r1, rn, kappa, v_f = x
    r = thresholds(r1, rn, n)
    p = density(r, lam, sigma)
    gl = np.column_stack((a1 * v + a2, a1 * v + a2))
    gr = np.column_stack((a3 * v + a4, a5 * v + a6))
    z = play_numpy(v, gl, np.vstack((r, r)), gr, np.vstack((r, kappa * r)), p).T  # both families
    d = np.empty(v.size, dtype=int)
    state, anchor = 1, v[0]
    for k, xk in enumerate(v):  # v' = direction of the last change beyond the dead band
        if state > 0:
            if xk > anchor:
                anchor = xk
            elif anchor - xk > deadband:
                state, anchor = -1, xk
        else:
            if xk < anchor:
                anchor = xk
            elif xk - anchor > deadband:
                state, anchor = 1, xk
        d[k] = state
    return np.where((d < 0) & (v <= v_f), z[1], z[0])


def best_time(fn, repeat: int) -> float:
    """Minimum wall time of ``repeat`` calls (s)."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20,000 samples instead of 100,000")
    args = ap.parse_args()
    n_samples = 20_000 if args.quick else 100_000
    _, v = loading_trajectory(np.random.default_rng(0), n_cycles=20, n_samples=n_samples)
    model = i2ris_egpi_model(n=30, deadband_counts=2.0, **paper_like_params("yaw+"))
    x = model.values
    model(v[:100])  # compile / load the cached kernels
    t_numba = best_time(lambda: model.evaluate(v, x), repeat=30)
    t_numpy = best_time(lambda: egpi_numpy(v, x, 30, 2.0), repeat=1)
    diff = float(np.max(np.abs(model.evaluate(v, x) - egpi_numpy(v, x, 30, 2.0))))
    print(f"EGPI, 2 stages x 31 operators, {n_samples} samples, one core")
    print(f"  compiled (numba): {t_numba * 1e3:8.3f} ms   (target <= 5 ms)")
    print(f"  numpy reference : {t_numpy * 1e3:8.1f} ms")
    print(f"  speed-up        : {t_numpy / t_numba:8.0f} x   (target >= 100 x)")
    print(f"  max |difference|: {diff:.2e} deg")
    ok = t_numba <= 5e-3 and t_numpy / t_numba >= 100 and diff < 1e-9
    print("ALL TARGETS MET" if ok else "SOME TARGETS MISSED")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
