"""The search data of the diagnosis: the dataset decimated to at most
``max_samples`` samples, its fitted and held-out masks, held-out units and loading
branch, and the check that a dataset holds enough for the workflow.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from i2ris_calib.data.dataset import Dataset
from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.diagnosis.cycles import dataset_cycles, holdout_units, loading_mask
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.model import Signals


@dataclass(frozen=True)
class SearchData:
    """Search data: decimated signals, angle (0 where not counted), the fitted and
    held-out masks, held-out units and the loading branch."""

    signals: Signals
    theta: np.ndarray
    fit: np.ndarray
    hold: np.ndarray
    units: np.ndarray
    loading: np.ndarray


#: Least fitted / held-out samples (angle measured, on the search signal) the
#: workflow accepts: the refits need many more residuals than parameters (a start
#: EGPI has 11 free, each effect adds up to 2), and the held-out test needs more
#: than a handful of held-out samples.
MIN_FITTED_SAMPLES = 50
MIN_HOLDOUT_SAMPLES = 20


def decimation_step(n: int, cfg: DiagnosisConfig) -> int:
    """Step k of the search signal (every k-th sample, at most ``max_samples``)."""
    return max(1, int(np.ceil(n / cfg.max_samples)))


def check_dataset(data: Dataset, config: DiagnosisConfig | None = None) -> None:
    """Raise a one-line CalibError unless the workflow can work with ``data``.

    The minimum (checked in this order):

    1. at least one held-out loading cycle. With the held-out rule
       (:func:`i2ris_calib.data.cycles.holdout_mask`) that means at least 2
       loading cycles, and one of them other than the first lying inside the input
       range of the others (a held-out cycle tests interpolation); the first cycle
       is never held out. Two such cycles are enough.
    2. at least :data:`MIN_FITTED_SAMPLES` fitted and :data:`MIN_HOLDOUT_SAMPLES`
       held-out samples with the angle measured on the search signal (every k-th
       sample, see :func:`decimation_step`).
    """
    cfg = config or DiagnosisConfig()
    where = f"{data.source} [{data.name}]" if data.source else data.name
    ok = np.isfinite(data.theta_deg)
    hold = data.holdout & ok
    if not hold.any():
        cyc = dataset_cycles(data.v)
        n_cyc = int(np.unique(cyc[data.in_direction]).size) if data.in_direction.any() else 0
        why = (
            "only 1 loading cycle"
            if n_cyc == 1
            else f"{n_cyc} loading cycles"
            + (
                ", but every cycle after the first leaves the input range of the others"
                if n_cyc >= 2
                else ""
            )
        )
        raise CalibError(
            f"{where}: {why}; diagnosis needs a held-out loading cycle, i.e. at least 2 "
            "loading cycles with the angle measured, one of them (not the first) inside "
            "the input range of the others: record more cycles (or check [fit] "
            "holdout_fraction > 0)"
        )
    step = decimation_step(data.n_samples, cfg)
    n_fit = int((data.fit_mask[::step]).sum())
    n_hold = int(hold[::step].sum())
    if n_fit < MIN_FITTED_SAMPLES or n_hold < MIN_HOLDOUT_SAMPLES:
        raise CalibError(
            f"{where}: {n_fit} fitted and {n_hold} held-out samples with the angle measured"
            + (f" (every {step}th sample)" if step > 1 else "")
            + f"; diagnosis needs at least {MIN_FITTED_SAMPLES} fitted and "
            f"{MIN_HOLDOUT_SAMPLES} held-out: record longer cycles or at a higher rate"
            + (" (or raise [diagnose] max_samples)" if step > 1 else "")
        )


def search_data(data: Dataset, cfg: DiagnosisConfig) -> tuple[SearchData, np.ndarray, int]:
    """Decimated search data, the full held-out mask and the decimation step."""
    check_dataset(data, cfg)
    theta_full = np.asarray(data.theta_deg, float)
    ok_full = np.isfinite(theta_full)
    hold_full = data.holdout & ok_full
    step = decimation_step(data.n_samples, cfg)
    idx = np.arange(0, data.n_samples, step)
    sig = data.signals.take(idx)
    # a read-only input owning its data cannot change during the search: the models
    # keep what they derive from it (runs of held samples, each tendon's input)
    v = np.array(sig.v, dtype=float)
    v.flags.writeable = False
    sig = replace(sig, v=v)
    th = theta_full[idx]
    ok = ok_full[idx]
    hold = hold_full[idx]
    fit = data.fit_mask[idx]
    units = holdout_units(dataset_cycles(data.v)[idx], hold)
    loading = loading_mask(data.v, data.bands.deadband)[idx]
    d = SearchData(sig, np.where(ok, th, 0.0), fit, hold, units, loading)
    return d, hold_full, step
