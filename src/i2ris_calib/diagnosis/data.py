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
from i2ris_calib.fitting.prehistory import InitialState, prehistory_signals, starts_at_rest
from i2ris_calib.model import Signals


@dataclass(frozen=True)
class SearchData:
    """Search data: decimated signals, angle (0 where not counted), the fitted and
    held-out masks, held-out units and the loading branch. ``relaxed``: the signals
    begin with the fit's pre-history (:func:`_after_prehistory`), whose first sample is
    relaxed by construction (the models' own start): a refit starts them at rest, not
    after a start state of its own (the fit's is the one answer)."""

    signals: Signals
    theta: np.ndarray
    fit: np.ndarray
    hold: np.ndarray
    units: np.ndarray
    loading: np.ndarray
    relaxed: bool = False


#: Least fitted / held-out samples (angle measured, on the search signal) the
#: workflow accepts: the refits need many more residuals than parameters (a start
#: EGPI has 11 free, each effect adds up to 2), and the held-out test needs more
#: than a handful of held-out samples.
MIN_FITTED_SAMPLES = 50
MIN_HOLDOUT_SAMPLES = 20


#: Input levels (quantiles of the recording's input) that a recording not starting at
#: rest must have reached, both, before its samples count in the diagnosis' loss.
BURN_IN_QUANTILES = (0.02, 0.98)
#: Largest share of a recording left out as burn-in (a recording whose input reaches
#: its range only late keeps at least the rest).
MAX_BURN_IN_FRACTION = 0.5


def _levels_reached(v: np.ndarray) -> int:
    """Index of the first sample by which ``v`` has reached both its low and high
    levels (:data:`BURN_IN_QUANTILES`), ``v.size`` if it never does."""
    lo, hi = np.quantile(v, BURN_IN_QUANTILES)
    low = np.flatnonzero(v <= lo)
    high = np.flatnonzero(v >= hi)
    if not low.size or not high.size:
        return v.size
    return int(max(low[0], high[0]))


def burn_in_samples(signals: Signals) -> int:
    """Samples at the start of a recording left out of the diagnosis' loss, int.

    A recording that starts at rest (:func:`~i2ris_calib.fitting.prehistory.starts_at_rest`:
    at zero, the lowest or the highest input) has none: the models' relaxed start is
    its state. One that starts mid-loop or moving has an unknown operator state; a
    play operator forgets its start once the input has moved by twice its threshold,
    so once the input has gone to both its low and its high level
    (:data:`BURN_IN_QUANTILES`, for the other motor's input too when it is measured)
    every operator up to half the range carries no trace of the start. The samples
    before that are the burn-in, at most :data:`MAX_BURN_IN_FRACTION` of the
    recording. The fit estimates the start state instead (``initial_state`` in
    fit.json); the diagnosis refits many models, and leaving the burn-in out keeps an
    unknown start from looking like an effect.
    """
    v = np.asarray(signals.v, dtype=float)
    if v.size < 2 or starts_at_rest(v):
        return 0
    n = _levels_reached(v)
    vo = signals.v_other
    if vo is not None and np.all(np.isfinite(vo)) and np.ptp(vo) > 0:
        n = max(n, _levels_reached(np.asarray(vo, dtype=float)))
    return int(min(n, int(MAX_BURN_IN_FRACTION * v.size)))


def start_rule(data: Dataset, initial_state: InitialState | None) -> tuple[int, str]:
    """(burn-in samples, the diagnosis' sentence on its start) of ``data``: (0, "") for
    a recording that starts at rest; for one that does not, with the start state the
    fit estimated (``initial_state``, :attr:`FitResult.initial_state`): no burn-in,
    every model runs after that pre-history (:func:`search_data`); without it: the
    burn-in of :func:`burn_in_samples`."""
    sig = data.signals
    v = np.asarray(sig.v, dtype=float)
    if v.size < 2 or starts_at_rest(v):
        return 0, ""
    head = f"the recording does not start at rest (input {float(v[0]):.6g} at its first sample)"
    if initial_state is not None:
        return 0, (
            f"{head}: every model runs after the start state the fit estimated (a "
            f"pre-history from {initial_state.v_from:.6g}), which is outside the loss"
        )
    n_burn = burn_in_samples(sig)
    t = sig.t_s
    span = f" ({float(t[n_burn] - t[0]):.3g} s)" if t is not None and n_burn < len(t) else ""
    return n_burn, (
        f"{head}: its first {n_burn} samples{span}, until the input had reached both ends "
        "of its range, are left out of the loss (the operators' start state is unknown "
        "there; give the fit's initial state to keep them)"
    )


def decimation_step(n: int, cfg: DiagnosisConfig) -> int:
    """Step k of the search signal (every k-th sample, at most ``max_samples``)."""
    return max(1, int(np.ceil(n / cfg.max_samples)))


def check_dataset(data: Dataset, config: DiagnosisConfig | None = None, n_burn: int = 0) -> None:
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

    Both count only the samples after the first ``n_burn`` (the burn-in of a
    recording that does not start at rest, :func:`start_rule`).
    """
    cfg = config or DiagnosisConfig()
    where = f"{data.source} [{data.name}]" if data.source else data.name
    ok = np.isfinite(data.theta_deg)
    counted = np.arange(data.n_samples) >= n_burn
    hold = data.holdout & ok & counted
    after = (
        f" after the burn-in of its first {n_burn} samples (it does not start at rest; "
        "diagnose(..., initial_state=) with the fit's start state keeps them)"
    )
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
            f"{where}: {why}{after if n_burn else ''}; diagnosis needs a held-out loading "
            "cycle, i.e. at least 2 loading cycles with the angle measured, one of them "
            "(not the first) inside the input range of the others: record more cycles "
            "(or check [fit] holdout_fraction > 0)"
        )
    step = decimation_step(data.n_samples, cfg)
    n_fit = int(((data.fit_mask & counted)[::step]).sum())
    n_hold = int(hold[::step].sum())
    if n_fit < MIN_FITTED_SAMPLES or n_hold < MIN_HOLDOUT_SAMPLES:
        raise CalibError(
            f"{where}: {n_fit} fitted and {n_hold} held-out samples with the angle measured"
            + (f" (every {step}th sample)" if step > 1 else "")
            + (after if n_burn else "")
            + f"; diagnosis needs at least {MIN_FITTED_SAMPLES} fitted and "
            f"{MIN_HOLDOUT_SAMPLES} held-out: record longer cycles or at a higher rate"
            + (" (or raise [diagnose] max_samples)" if step > 1 else "")
        )


def search_data(
    data: Dataset, cfg: DiagnosisConfig, initial_state: InitialState | None = None
) -> tuple[SearchData, np.ndarray, int]:
    """Decimated search data, the full held-out mask and the decimation step.

    A recording that does not start at rest (:func:`start_rule`) runs after the fit's
    estimated pre-history (``initial_state``), prepended to the search signals with
    nothing counted there; without one its burn-in is left out of the loss.
    """
    n_burn, note = start_rule(data, initial_state)
    check_dataset(data, cfg, n_burn)
    theta_full = np.asarray(data.theta_deg, float)
    counted = np.arange(data.n_samples) >= n_burn
    ok_full = np.isfinite(theta_full)
    hold_full = data.holdout & ok_full & counted
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
    fit = (data.fit_mask & counted)[idx]
    units = holdout_units(dataset_cycles(data.v)[idx], hold)
    loading = loading_mask(data.v, data.bands.deadband)[idx]
    d = SearchData(sig, np.where(ok, th, 0.0), fit, hold, units, loading)
    if initial_state is not None and note:
        d = _after_prehistory(d, initial_state)
    return d, hold_full, step


def _after_prehistory(d: SearchData, st: InitialState) -> SearchData:
    """``d`` with the fit's pre-history ``st`` (the ramps from ``v_turn3`` via ``v_turn2``, ``v_turn``
    and ``v_from``, the other motor's first when estimated, the replayed first cycle)
    prepended (nothing counted there)."""
    other = None
    if st.other_v_from is not None:
        o_turn = st.other_v_from if st.other_v_turn is None else st.other_v_turn
        o_turn2 = st.other_v_turn2
        other = (o_turn if o_turn2 is None else o_turn2, o_turn, st.other_v_from)
    sig, n_pre = prehistory_signals(
        d.signals,
        st.v_from,
        cycle=st.cycle_samples,
        v_turn=st.v_turn,
        other_levels=other,
        v_turn2=st.v_turn2,
        v_turn3=st.v_turn3,
    )

    def pad(a: np.ndarray, value) -> np.ndarray:
        return np.concatenate([np.full(n_pre, value, dtype=a.dtype), a])

    return SearchData(
        sig,
        pad(d.theta, 0.0),
        pad(d.fit, False),
        pad(d.hold, False),
        pad(d.units, -1),
        pad(d.loading, False),
        relaxed=True,
    )
