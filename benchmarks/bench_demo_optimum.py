"""Does the default EGPI fit of the README demo reach the best of 16 starts? (issue 31 b)

Run: ``NUMBA_NUM_THREADS=1 python benchmarks/bench_demo_optimum.py [SYNCED_CSV]``
(default ``runs/sample/session/sync/synced.csv``, written by ``bash scripts/demo.sh``
or ``i2ris-calib run sample_data/session --out runs/sample``; ``--starts N``: the
reference's starts, default 16; ``--kind``: default egpi).

For each motion-direction dataset of the synced CSV (axes yaw and pitch, read as
``i2ris-calib fit`` reads them: :func:`~i2ris_calib.io.synced.datasets_for_fit`, the
default model choice), the kind is fitted twice by the product's path (the kinds it
nests first, passed on: :func:`~i2ris_calib.commands.fit.fit_every_kind`): with the
default :class:`~i2ris_calib.fitting.config.FitConfig` and with ``n_starts = N`` (as
``[fit] n_starts = 16`` in a ``--config`` TOML; the nested GPI gets them too). Printed
per dataset: the default fit's cost (sum of squared residuals over the fitted
samples, ``FitResult.chisqr``), the best-of-N fit's cost, their ratio and the CPU
seconds of each chain. Target: every dataset's default cost within 2 % of the
best-of-N one (ratio <= 1.02). Exit status 1 when a dataset misses it.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

from i2ris_calib.commands.fit import fit_every_kind  # noqa: E402
from i2ris_calib.fitting.config import FitConfig  # noqa: E402
from i2ris_calib.hysteresis.registry import kind_info  # noqa: E402
from i2ris_calib.io.synced import datasets_for_fit  # noqa: E402

DEFAULT_CSV = Path("runs/sample/session/sync/synced.csv")
AXES = ("yaw", "pitch")
#: The default fit's cost may be at most this times the best-of-N fit's
TOLERANCE = 1.02


def chain(kind: str) -> list[str]:
    """``kind`` and the kinds nested in it, innermost first (egpi: gpi, egpi)."""
    nested = kind_info(kind).nested
    return [kind] if nested is None else [*chain(nested), kind]


def chain_costs(csv: Path, kind: str, config: FitConfig) -> dict[str, tuple[float, float]]:
    """{dataset name: (the kind's fit cost, CPU s of the dataset's chain)} over both
    axes of ``csv``, fitted by ``config``."""
    out = {}
    for axis in AXES:
        datasets, _ = datasets_for_fit([csv], axis, config)
        for d in datasets:
            t0 = time.process_time()
            ((_, res),) = fit_every_kind([d], chain(kind), config)
            out[d.name] = (float(res[kind].chisqr), time.process_time() - t0)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("synced", nargs="?", type=Path, default=DEFAULT_CSV, help="synced CSV")
    ap.add_argument("--starts", type=int, default=16, help="starts of the reference fit")
    ap.add_argument("--kind", default="egpi", help="model kind (default egpi)")
    args = ap.parse_args(argv)
    if not args.synced.is_file():
        ap.error(f"{args.synced}: no such file; run the demo first (bash scripts/demo.sh)")
    default = chain_costs(args.synced, args.kind, FitConfig())
    best = chain_costs(args.synced, args.kind, replace(FitConfig(), n_starts=args.starts))
    print(f"== {args.kind}: default fit vs best of {args.starts} starts, {args.synced}")
    print(f"{'dataset':10s} {'default':>12s} {f'best-of-{args.starts}':>12s} "
          f"{'ratio':>8s} {'cpu def':>7s} {'cpu ref':>7s}")  # fmt: skip
    ok = True
    for name, (cost, cpu) in default.items():
        ref, ref_cpu = best[name]
        ratio = cost / ref if ref > 0 else float("inf")
        ok &= ratio <= TOLERANCE
        flag = "" if ratio <= TOLERANCE else "  <-- above target"
        print(f"{name:10s} {cost:12.6g} {ref:12.6g} {ratio:8.4f} {cpu:7.2f} {ref_cpu:7.2f}{flag}")
    print(f"target: default <= {TOLERANCE} x best-of-{args.starts} on every dataset:",
          "met" if ok else "MISSED")  # fmt: skip
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
