"""Run every benchmark and print its figures: ``python benchmarks/run_all.py [--quick]``.

Each ``bench_*.py`` beside this file is run in its own process (so timings are not
disturbed by the others), in alphabetical order; ``--quick`` is passed on. The
model-stage targets of issue 8 are ``bench_model_stage.py`` (random EGPI truths over
whole histories, a rendered exact-EGPI session, fit speed); it renders a ~105 s
session (``--quick``: ~50 s at 320x256), so the full run takes several minutes more.
Single-threaded numba/BLAS in every child (NUMBA_NUM_THREADS / OMP_NUM_THREADS = 1
unless set), as the figures in docs/benchmarks.md were measured.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path


def main(argv: list[str]) -> int:
    here = Path(__file__).resolve().parent
    failed = []
    for bench in sorted(here.glob("bench_*.py")):
        print(f"\n===== {bench.name} =====", flush=True)
        t0 = time.perf_counter()
        env = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", **os.environ}
        rc = subprocess.call([sys.executable, str(bench), *argv], env=env)
        print(f"----- {bench.name}: exit {rc}, {time.perf_counter() - t0:.1f} s", flush=True)
        if rc != 0:
            failed.append(bench.name)
    print(
        "\nall benchmarks passed their targets"
        if not failed
        else f"\nmissed targets: {', '.join(failed)}"
    )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
