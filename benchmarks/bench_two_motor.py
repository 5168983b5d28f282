"""Two-motor benchmark: both motors at once, the pitch angle following the yaw motor (issue 20).

Run: ``NUMBA_NUM_THREADS=1 python benchmarks/bench_two_motor.py`` (``--draws N``;
``--no-diagnose``: the fit targets only).

``--draws`` seeded draws of :func:`i2ris_calib.simulation.two_motor.simulate_two_motor`:
two antagonistic tendons per axis (a GPI per tendon, different gains per side), offsets
within +-10 deg, pitch coupled to the yaw joint's bend at U(0.3, 0.8) of its own gain,
circles, figure-eights and holds through zero, 30 Hz (3000 samples) and 5 Hz (600)
alternately, noise U(0.15, 0.5) deg, the recording starting mid-loop. Each draw is
written as a synced CSV and read by the commands' own path
(:func:`i2ris_calib.commands.fit.datasets_for_fit`: the default model choice, no flags).

Targets, both axes: the default model's held-out RMSE <= 1.2 x noise; its largest
output jump between consecutive samples <= the truth's + 3 noise sd. ``diagnose``
(default settings, the dataset and starting model it chooses) names the coupling on
pitch in >= 9/10 draws.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from i2ris_calib.commands.diagnose import diagnosis_dataset  # noqa: E402
from i2ris_calib.commands.fit import datasets_for_fit, fit_every_kind  # noqa: E402
from i2ris_calib.diagnosis.config import DiagnosisConfig  # noqa: E402
from i2ris_calib.diagnosis.workflow import diagnose_from_starts  # noqa: E402
from i2ris_calib.fitting.config import FitConfig  # noqa: E402
from i2ris_calib.simulation.two_motor import simulate_two_motor  # noqa: E402


def write(rec, path: Path) -> None:
    frame = pd.DataFrame(rec.columns())
    frame["status"] = "measured"
    frame["frame"] = np.arange(len(frame))
    frame.to_csv(path, index=False)


def one_draw(seed: int, rate: float, n: int, folder: Path, diagnose: bool):
    rec = simulate_two_motor(seed, n, rate)
    csv = folder / f"draw{seed}.csv"
    write(rec, csv)
    config = FitConfig()
    ok = True
    for axis, truth in (("yaw", rec.yaw_true_deg), ("pitch", rec.pitch_true_deg)):
        t0 = time.perf_counter()
        datasets, choice = datasets_for_fit([csv], axis, config)
        ((d, res),) = fit_every_kind(datasets, choice.kinds, config)
        dt = time.perf_counter() - t0
        r = res[choice.main]
        ratio = r.holdout_metrics.rmse_deg / rec.noise_deg
        jump = np.abs(np.diff(r.predict(d.signals))).max() - np.abs(np.diff(truth)).max()
        good = ratio <= 1.2 and jump <= 3 * rec.noise_deg
        ok &= good
        print(
            f"{seed:4d} {rate:4.0f} {n:5d} {rec.noise_deg:5.3f} {rec.coupling:5.2f} {axis:5s} "
            f"{choice.main:13s} {ratio:8.3f} {jump / rec.noise_deg:+8.2f} {dt:6.1f}s  "
            f"{'ok' if good else 'MISSED'}",
            flush=True,
        )
    named = None
    if diagnose:
        t0 = time.perf_counter()
        dset = diagnosis_dataset(csv, "pitch", "auto", config)
        auto = diagnose_from_starts(dset, DiagnosisConfig(), config)
        named = "axis_coupling" in auto.diagnosis.named_effects
        print(
            f"     diagnose pitch{dset.direction} from {auto.start}: "
            f"{', '.join(auto.diagnosis.named_effects) or 'nothing'} "
            f"({time.perf_counter() - t0:.0f} s) {'names coupling' if named else 'MISSED'}",
            flush=True,
        )
    return ok, named


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=10)
    ap.add_argument("--no-diagnose", action="store_true")
    args = ap.parse_args()
    print("seed rate     n noise  coup axis  model         hold/sd  jump-truth/sd  time")
    fits_ok, named = True, []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.draws):
            rate, n = (30.0, 3000) if i % 2 == 0 else (5.0, 600)
            ok, nm = one_draw(200 + i, rate, n, Path(tmp), not args.no_diagnose)
            fits_ok &= ok
            if nm is not None:
                named.append(nm)
    print("fit targets (held-out <= 1.2 x noise, jump <= truth + 3 sd, both axes):",
          "met" if fits_ok else "MISSED")  # fmt: skip
    if named:
        k = sum(named)
        need = int(np.ceil(0.9 * len(named)))
        print(f"diagnose names the coupling: {k}/{len(named)} (target >= {need}):",
              "met" if k >= need else "MISSED")  # fmt: skip
        fits_ok &= k >= need
    return 0 if fits_ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
