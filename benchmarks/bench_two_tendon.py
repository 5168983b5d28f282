"""Two-tendon benchmark: an axis driven through zero, fitted by the default path (issue 20).

Run: ``NUMBA_NUM_THREADS=1 python benchmarks/bench_two_tendon.py`` (``--draws N``,
``--quick``: 3 draws, no speed part).

1. Accuracy: ``--draws`` seeded draws of a two-tendon axis (``presets.
   random_two_tendon_params``: a GPI per tendon with its own gain, offset theta0 in
   +-10 deg) driven through zero by loops of varying amplitude and holds
   (``presets.through_zero_trajectory``), the recording starting mid-loop; 5 Hz
   (600 samples) and 30 Hz (3000 samples) alternately, noise U(0.15, 0.5) deg. The
   default path chooses the model from the recording (``data.excursions``,
   ``fitting.pipeline.choose_model``) and fits its kinds. Targets: the chosen input is
   signed, the default model's held-out RMSE <= 1.2 x noise, its largest output jump
   between consecutive samples <= the truth's + 3 noise sd.
2. Speed: the default kinds on a 50,000-sample recording (30 Hz); target <= 5 s per
   model on one core (compiled kernels warm).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from i2ris_calib.data.dataset import direction_datasets, input_bands  # noqa: E402
from i2ris_calib.data.excursions import excursions  # noqa: E402
from i2ris_calib.fitting.config import FitConfig  # noqa: E402
from i2ris_calib.fitting.pipeline import choose_model, fit_dataset  # noqa: E402
from i2ris_calib.hysteresis.presets import (  # noqa: E402
    random_two_tendon_params,
    through_zero_trajectory,
)
from i2ris_calib.hysteresis.registry import SIGNED_DEFAULT, model_for_kind  # noqa: E402


def draw(seed: int, n: int, rate_hz: float, noise: float | None = None):
    """(t s, signed input counts, measured angle deg, true angle deg, noise sd deg)."""
    rng = np.random.default_rng(seed)
    truth = random_two_tendon_params(rng)
    t, v, start = through_zero_trajectory(rng, n, rate_hz)
    y = model_for_kind("agpi").with_values(truth)(v)[start:]
    sd = float(rng.uniform(0.15, 0.5)) if noise is None else noise
    return t[start:], v[start:], y + rng.normal(0.0, sd, y.size), y, sd, truth["theta0"]


def default_fit(t, v, theta, config: FitConfig):
    """The default path: the model choice, then its kinds on its datasets (fit order)."""
    recording = excursions(v, input_bands(v).zero_band, t)
    choice = choose_model(recording, config)
    datasets = direction_datasets(
        "yaw", t, v, theta, signed=choice.signed, holdout_fraction=config.holdout_fraction
    )
    fits = []
    for d in datasets:
        out = {}
        for k in choice.kinds:
            out[k] = fit_dataset(k, d, config, out)
        fits.append((d, out))
    return choice, fits


def accuracy(n_draws: int, config: FitConfig) -> bool:
    ok = True
    print("seed  rate  n     offset  noise  model            hold/noise  jump-truth_jump (deg)")
    for i in range(n_draws):
        rate, n = (30.0, 3000) if i % 2 == 0 else (5.0, 600)
        t, v, theta, y, sd, theta0 = draw(100 + i, n, rate)
        choice, fits = default_fit(t, v, theta, config)
        (d, res), *_ = fits
        kind = SIGNED_DEFAULT if SIGNED_DEFAULT in res else choice.kinds[-1]
        r = res[kind]
        ratio = r.holdout_metrics.rmse_deg / sd
        jump = np.abs(np.diff(r.predict(d.signals))).max() - np.abs(np.diff(y)).max()
        good = choice.signed and ratio <= 1.2 and jump <= 3 * sd
        ok &= good
        print(
            f"{100 + i:4d}  {rate:4.0f}  {n:5d} {theta0:+7.2f}  {sd:5.3f}  {kind:15s}  "
            f"{ratio:10.3f}  {jump:+8.3f} (<= {3 * sd:.2f})  {'ok' if good else 'MISSED'}"
        )
    return ok


def speed(config: FitConfig) -> None:
    t, v, theta, _, sd, _ = draw(7, 50_000, 30.0, 0.25)
    warm = draw(8, 2000, 30.0, 0.25)
    default_fit(*warm[:3], config)  # compile
    recording = excursions(v, input_bands(v).zero_band, t)
    choice = choose_model(recording, config)
    (d,) = direction_datasets("yaw", t, v, theta, signed=True)
    out = {}
    for k in choice.kinds:
        t0 = time.perf_counter()
        out[k] = fit_dataset(k, d, config, out)
        dt = time.perf_counter() - t0
        print(
            f"50,000 samples, {k}: {dt:.2f} s (target <= 5 s), held-out RMSE "
            f"{out[k].holdout_metrics.rmse_deg / sd:.3f} x noise"
        )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    config = FitConfig()
    ok = accuracy(3 if args.quick else args.draws, config)
    print("accuracy targets:", "met" if ok else "MISSED")
    if not args.quick:
        speed(config)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
