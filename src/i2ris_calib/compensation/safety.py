"""Safety of a command sequence: up-and-back spikes, the entry ramp from the start state,
the conditioning sweep (the rate limit: :mod:`.rate`).

Pure array code (no files, no printing); docs/compensate.md ("Safe by default").
"""

from __future__ import annotations

import numpy as np

from i2ris_calib.errors import CalibError

#: An output excursion that returns is a spike when it leaves the target by more than
#: ``max(SPIKE_MIN_DEG, SPIKE_TOL_FACTOR * tol_deg)`` (deg) on top of the target's own
#: motion (:func:`find_spikes`)
SPIKE_MIN_DEG = 0.05
SPIKE_TOL_FACTOR = 10.0
#: A command excursion that returns is a spike when both its steps exceed this share of
#: the input range (and 3 quanta)
SPIKE_RANGE_SHARE = 0.01
#: The most commands one ramp (the entry ramp, a leg of the conditioning sweep) may take
#: (28 h at 100 Hz): a rate limit that needs more is a mistake (counts/min for counts/s?),
#: refused before the ramp is allocated (:func:`ramp_commands`)
MAX_RAMP_COMMANDS = 10_000_000


def ramp_commands(dist: float, max_rate: float, dt_s: float) -> float:
    """How many commands, one every ``dt_s`` s, a ramp over ``dist`` input units takes at
    ``max_rate`` per second (a float: ``inf`` for a rate of 0; 0 without a limit)."""
    if not np.isfinite(max_rate) or dist == 0:
        return 0.0
    per = float(max_rate) * float(dt_s)
    return float(np.ceil(abs(float(dist)) / per)) if per > 0 else float("inf")


def find_spikes(
    u: np.ndarray,
    y: np.ndarray,
    target: np.ndarray,
    tol_deg: float,
    v_range: float,
    quantum: float,
) -> np.ndarray:
    """Samples ``k`` where the command makes a one-sample excursion that returns.

    The command reverses at ``k`` (``(u[k] - u[k-1]) (u[k+1] - u[k]) < 0``) and either
    both command steps exceed ``max(3 quantum, SPIKE_RANGE_SHARE v_range)``, the command
    comes back (``|u[k+1] - u[k-1]|`` below half a step) while the target stays (it
    moves less than the output threshold below from ``k-1`` to ``k+1`` and does not go
    up and back by more) (a command spike), or the output also reverses there with both steps larger than the target's
    own change plus ``max(SPIKE_MIN_DEG, SPIKE_TOL_FACTOR tol_deg)`` and leaves the
    target by that much (an output spike: a few counts across an output step of the
    model, as under a rate limit).

    Returns
    -------
    ndarray of int
        Sorted sample indices (1 .. n-2).
    """
    u = np.asarray(u, dtype=float)
    if u.size < 3:
        return np.zeros(0, dtype=int)
    d1 = u[1:-1] - u[:-2]
    d2 = u[2:] - u[1:-1]
    rev = d1 * d2 < 0
    s_cmd = max(3.0 * quantum, SPIKE_RANGE_SHARE * float(v_range))
    s_deg = max(SPIKE_MIN_DEG, SPIKE_TOL_FACTOR * float(tol_deg))
    e1 = y[1:-1] - y[:-2]
    e2 = y[2:] - y[1:-1]
    f1 = target[1:-1] - target[:-2]
    f2 = target[2:] - target[1:-1]
    g1, g2 = np.abs(f1), np.abs(f2)
    # a target that itself goes up and back there asks for the excursion
    asked = (f1 * f2 < 0) & (g1 > s_deg) & (g2 > s_deg)
    size = np.minimum(np.abs(d1), np.abs(d2))
    back = np.abs(u[2:] - u[:-2]) < 0.5 * size  # the command comes back
    still = np.abs(target[2:] - target[:-2]) <= s_deg  # ... where the target stays
    cmd = rev & (size > s_cmd) & back & still & ~asked
    out = (
        rev
        & (e1 * e2 < 0)
        & (np.abs(e1) > g1 + s_deg)
        & (np.abs(e2) > g2 + s_deg)
        & (np.abs(y[1:-1] - target[1:-1]) > s_deg)
    )
    return np.flatnonzero(cmd | out) + 1


def entry_ramp(
    v_start: float, v_first: float, max_rate: float, dt_s: float, quantum: float
) -> np.ndarray:
    """The commands from ``v_start`` to ``v_first`` (exclusive of both) at no more than
    ``max_rate`` per second, one every ``dt_s`` seconds: a straight ramp in whole
    multiples of ``quantum`` (real-valued for 0), shape (m,). Empty when one step does.

    A monotone ramp leaves the operators of a play-type model where one step would,
    so the inverse can take the first target sample as one step from ``v_start``.
    CalibError when it would take more than :data:`MAX_RAMP_COMMANDS` commands.
    """
    dist = float(v_first) - float(v_start)
    if dist == 0 or not np.isfinite(max_rate):
        return np.zeros(0)
    need = ramp_commands(dist, max_rate, dt_s)
    if need > MAX_RAMP_COMMANDS:
        raise CalibError(
            f"a ramp of {abs(dist):g} counts at the rate limit {max_rate:g} counts/s, one "
            f"command every {dt_s:g} s, would take {need:.3g} commands (at most "
            f"{MAX_RAMP_COMMANDS:.0e}); give a rate limit of at least "
            f"{abs(dist) / (MAX_RAMP_COMMANDS * dt_s):.3g} counts/s"
        )
    per = max_rate * dt_s
    if quantum > 0 and per >= quantum:
        per = np.floor(per / quantum + 1e-9) * quantum
    m = int(np.ceil(abs(dist) / per - 1e-9))
    if m <= 1:
        return np.zeros(0)
    step = per * np.arange(1, m)
    if quantum > 0:  # whole quanta; less than one per sample: one once the time allows
        step = np.floor(step / quantum + 1e-9) * quantum
    return float(v_start) + np.sign(dist) * np.minimum(step, abs(dist))


def conditioning_sweep(
    v_start: float,
    lo: float,
    hi: float,
    max_rate: float,
    dt_s: float,
    quantum: float,
    last: str = "lo",
) -> np.ndarray:
    """A conditioning (homing) sweep: from ``v_start`` to one end of ``[lo, hi]``, then
    to the other end ``last`` (``"lo"`` or ``"hi"``), straight ramps at no more than
    ``max_rate`` per second, one command every ``dt_s`` seconds, shape (m,) (ends
    included, ``v_start`` not). Real-valued for ``quantum`` 0, else whole multiples.

    A play operator's state after a monotone input move across the whole range it was
    fitted on no longer depends on what came before (its memory is wiped): after the
    sweep the model and the robot are in the same known state whatever the robot did
    before, which the model's virgin state at rest is not unless the fit's recording
    started at rest. Without a rate limit (``inf``) the sweep is the two ends.
    """
    if last not in ("lo", "hi"):
        raise ValueError(f"last must be 'lo' or 'hi', got {last!r}")
    first_end, last_end = (hi, lo) if last == "lo" else (lo, hi)
    out = []
    v = float(v_start)
    for end in (first_end, last_end):
        if end == v:
            continue
        if np.isfinite(max_rate):
            out.append(entry_ramp(v, end, max_rate, dt_s, quantum))
        out.append(np.array([float(end)]))
        v = float(end)
    return np.concatenate(out) if out else np.zeros(0)
