"""The recording's start state and the synthetic pre-history a fit runs a model after.

A recording that does not start at rest (:func:`starts_at_rest`) starts with the
operators in a state the models' own relaxed start does not give. The fit
(:func:`~i2ris_calib.fitting.fit.fit_model`) runs the model after a synthetic
pre-history instead: the input ramps through fitted levels to its first value
(:func:`prehistory_signals`; the model wrapped so, :class:`_FromLevel`), optionally
replaying the recording's own first cycle (:func:`opening_cycle`), and the result keeps
the levels as an :class:`InitialState`. What is here is that state and that
pre-history; how the levels are searched is the optimiser's
(:mod:`~i2ris_calib.fitting.fit`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from i2ris_calib.model import Model, Parameter, Signals
from i2ris_calib.model import analytic_method as _analytic_jacobian

#: A recording whose first input lies within this fraction of the input range of zero,
#: of its lowest or of its highest value starts at rest: the models' own start (every
#: operator relaxed, ``w[-1] = 0`` clamped into the band at ``v[0]``) is the state
#: reached by coming there monotonically, and no initial state is estimated.
REST_TOLERANCE = 0.01
#: Longest synthetic pre-history (samples).
MAX_PREHISTORY = 5000


@dataclass(frozen=True)
class InitialState:
    """The state at the first sample of a recording that does not start at rest.

    The models start with every operator relaxed at ``v[0]`` (the state of an input
    that came up from zero), which is wrong for a recording that starts mid-loop:
    an operator pulled the other way, a first angle off by up to the loop's width.
    The fitter then runs every model after a synthetic pre-history, the input
    ramping from a level ``v_from`` (operators relaxed there) to ``v[0]`` at the
    recording's own typical speed, and fits ``v_from`` with the other parameters
    (a profile search over the input range). ``v_from`` above ``v[0]``: the
    recording starts on a falling branch that turned at ``v_from``; at or below it
    (or zero): on the loading branch. One level cannot stand for a nested history
    of several reversals; such a start keeps a smaller error until the input has
    swept the loop. The rule works for every model: it only changes the input the
    model runs on.

    A recording whose input comes back to its first value in the direction it left it,
    after sweeping its range (a periodic lab input: circles, figure-eights, sines),
    may also start after its own first cycle replayed (:func:`opening_cycle`): the
    pre-history is then the ramp, then the recording's first ``cycle_samples``
    samples of this motor, so the state of every operator the loop sweeps is the
    loop's own (the other motor, for a model that reads it, holds its first value
    meanwhile: its state is its own levels'). The fit tries the start with and without
    the replayed cycle and keeps the lower cost.

    Attributes
    ----------
    v_from : float
        Fitted level (input unit) the input came from.
    n_samples : int
        Samples of the synthetic pre-history (the ramp and the replayed cycle).
    v0 : float
        First input value.
    text : str
        One sentence for the terminal and fit.json.
    cycle_samples : int
        Samples of the recording's opening replayed after the ramp (0: none).
    v_turn : float or None
        An earlier turning point of the pre-history: the operators relaxed at
        ``v_turn``, the input ramps to ``v_from``, then to ``v[0]`` (None or equal to
        ``v_from``: one ramp). Two levels stand for the last two reversals before
        the recording (a loop's maximum and minimum), which may lie beyond the
        recording's own range.
    v_turn2 : float or None
        A turning point before ``v_turn``: the operators relaxed at ``v_turn2``, the
        input ramps to ``v_turn``, to ``v_from`` and to ``v[0]`` (None or equal to
        ``v_turn``: as without it). Three levels stand for the staircase of the last
        three reversals (a loop, then a smaller one inside it: the wiping-out memory of
        a recording that starts after loops of varying amplitude).
    other_v_turn, other_v_from : float or None
        The other motor's pre-history, for a model with a state of its input
        (hysteretic coupling): relaxed at ``other_v_turn``, ramping to
        ``other_v_from`` and to its first value ``v0_other``, before this motor's
        ramps (None: it held its first value, relaxed there). The other motor holds its
        first value during the replayed cycle: its state is its levels' (a cycle of
        this motor's is not one of the other's, and a recording's first cycle need not
        end at the turning points the other motor came from).
    v0_other : float or None
        The other motor's first input value (with its levels).
    v_turn3 : float or None
        A turning point before ``v_turn2`` (relaxed there, ramping to ``v_turn2``; None:
        as without it): four levels, a staircase of the last four reversals, for a
        short recording that starts after loops of shrinking amplitude
        (:func:`~i2ris_calib.fitting.fit.own_levels`).
    other_v_turn2 : float or None
        A turning point of the other motor before ``other_v_turn`` (relaxed there;
        None: as without it). Each side of the other input is a GPI of its own that
        remembers its largest excursion through the other side's: a loop's largest
        excursion on either side and the turning point of the current one are three
        levels.
    """

    v_from: float
    n_samples: int
    v0: float
    text: str
    cycle_samples: int = 0
    v_turn: float | None = None
    other_v_turn: float | None = None
    other_v_from: float | None = None
    v0_other: float | None = None
    v_turn2: float | None = None
    other_v_turn2: float | None = None
    v_turn3: float | None = None

    def as_dict(self) -> dict:
        """JSON-ready form (``v_turn3`` only when set: a state of three own levels
        reads as it did)."""
        extra = {} if self.v_turn3 is None else {"v_turn3": self.v_turn3}
        return extra | {
            "v_turn2": self.v_turn2,
            "other_v_turn2": self.other_v_turn2,
            "other_v_turn": self.other_v_turn,
            "other_v_from": self.other_v_from,
            "v0_other": self.v0_other,
            "v_turn": self.v_turn,
            "v_from": self.v_from,
            "n_samples": self.n_samples,
            "v0": self.v0,
            "text": self.text,
            "cycle_samples": self.cycle_samples,
        }

    def scaled(
        self, factor: float, v0: float | None = None, v0_other: float | None = None
    ) -> InitialState:
        """This state for the input ``v * factor`` (a fit in a rescaled input unit
        converted back, :func:`~i2ris_calib.fitting.pipeline.input_scale`): every level
        (``v_from``, ``v_turn``, ``v_turn2``, ``v_turn3``, ``v0`` and the other motor's) multiplied by
        ``factor``, :attr:`text` made anew from the fields (:func:`state_text`).

        ``v0``, ``v0_other``: the first inputs in the new unit, when known, in place of
        the products (which may differ from them in the last bit:
        :meth:`~i2ris_calib.fitting.result.FitResult.predict` knows the fit's own data by
        its first input). ``n_samples`` and ``cycle_samples`` stay: the pre-history's
        steps scale with the input."""
        f = float(factor)

        def times(x: float | None) -> float | None:
            return None if x is None else float(x) * f

        out = replace(
            self,
            v_from=float(self.v_from) * f,
            v0=float(self.v0) * f if v0 is None else float(v0),
            v_turn=times(self.v_turn),
            v_turn2=times(self.v_turn2),
            v_turn3=times(self.v_turn3),
            other_v_turn=times(self.other_v_turn),
            other_v_from=times(self.other_v_from),
            other_v_turn2=times(self.other_v_turn2),
            v0_other=times(self.v0_other) if v0_other is None else float(v0_other),
        )
        return replace(out, text=state_text(out))


def state_text(st: InitialState) -> str:
    """The sentence of :attr:`InitialState.text`, from the state's other fields (its
    ``text`` is not read): where the recording starts, the branch and the levels of the
    pre-history (the other motor's too), the replayed cycle and its length."""
    u = st.v_from
    ut = u if st.v_turn is None else st.v_turn
    ut2 = ut if st.v_turn2 is None else st.v_turn2
    ut3 = ut2 if st.v_turn3 is None else st.v_turn3
    branch = f"a falling branch that turned at {u:.6g}" if u > st.v0 else "the loading branch"
    lv = (ut3, ut2, ut, u)
    path = [x for i, x in enumerate(lv) if i == 0 or x != lv[i - 1]]
    via = "".join(f" via {x:.6g}" for x in path[1:])
    if st.other_v_from is not None:
        o_from = st.other_v_from
        o_turn = o_from if st.other_v_turn is None else st.other_v_turn
        o_turn2 = o_turn if st.other_v_turn2 is None else st.other_v_turn2
        vo0 = st.v0_other
        o_path = [x for i, x in enumerate((o_turn2, o_turn, o_from, vo0))
                  if i == 0 or x != (o_turn2, o_turn, o_from, vo0)[i - 1]]  # fmt: skip
        if len(o_path) > 1:
            branch += (
                f"; the other motor from {o_path[0]:.6g}"
                + "".join(f" via {x:.6g}" for x in o_path[1:-1])
                + f" to {vo0:.6g}"
            )
    cycle = st.cycle_samples
    replay = (
        f", then the recording's first {cycle} samples (its first cycle) replayed" if cycle else ""
    )
    return (
        f"the recording starts mid-range (input {st.v0:.6g}, not at rest): initial state "
        f"fitted as {branch} (pre-history from {ut3:.6g}{via}{replay}, {st.n_samples} samples)"
    )


def starts_at_rest(v: np.ndarray) -> bool:
    """True when the first input is within ``REST_TOLERANCE`` of the input range of
    zero, of the lowest or of the highest input: the models' relaxed start applies."""
    v = np.asarray(v, dtype=float)
    span = float(np.ptp(v)) if v.size else 0.0
    if span <= 0:
        return True
    tol = REST_TOLERANCE * span
    v0 = float(v[0])
    return abs(v0) <= tol or v0 - float(v.min()) <= tol or float(v.max()) - v0 <= tol


def reads_other_state(model: Model) -> bool:
    """True for a model with a state of the other motor's input (hysteretic coupling:
    its base has ``other_input_terms``)."""
    return hasattr(innermost(model), "other_input_terms")


def signals_start_at_rest(s: Signals, model: Model | None = None) -> bool:
    """:func:`starts_at_rest` of the input and, for a ``model`` with a state of the
    other motor's input (hysteretic coupling: ``other_input_terms``) when that input
    is measured, of that one too: such a model's state is both motors'."""
    if not starts_at_rest(s.v):
        return False
    vo = s.v_other
    if vo is None or model is None or not reads_other_state(model):
        return True
    vo = np.asarray(vo, dtype=float)
    return not np.all(np.isfinite(vo)) or starts_at_rest(vo)


def opening_cycle(v: np.ndarray) -> int:
    """Samples of the recording's first cycle: the input leaves its first value
    ``v[0]`` in one direction, crosses it the other way, then crosses it again in the
    first direction; the index of that last crossing (0 when there is none within the
    first half of the recording, or within :data:`MAX_PREHISTORY`).

    On a periodic input (a sine, circles, figure-eights) that is one period; on the
    paper's protocol, the rest of the excursion, the rest at zero and the next
    excursion's way back up to ``v[0]``. Moves within 1 % of the input range of
    ``v[0]`` do not count (encoder jitter).

    Parameters
    ----------
    v : ndarray, shape (n,)
        Input (input unit).

    Returns
    -------
    int
        ``k``: ``v[:k]`` replayed before ``v`` continues into ``v[0]`` as the input did.
    """
    v = np.asarray(v, dtype=float)
    n = v.size
    if n < 8 or np.ptp(v) <= 0:
        return 0
    v0, tol = float(v[0]), 0.01 * float(np.ptp(v))
    limit = min(n // 2, MAX_PREHISTORY)
    side = np.where(v[:limit] > v0 + tol, 1, np.where(v[:limit] < v0 - tol, -1, 0))
    moved = side[side != 0]
    idx = np.flatnonzero(side != 0)
    if moved.size < 3:
        return 0
    d0 = moved[0]
    back = np.flatnonzero(moved == -d0)
    if not back.size:
        return 0
    again = np.flatnonzero(moved[back[0] :] == d0)
    if not again.size:
        return 0
    # the last sample on the other side (or in the band) before the input is beyond
    # v[0] in the first direction again: v[:k] then v continues as the input did
    j = idx[back[0] + again[0]]
    below = np.flatnonzero((v[:j] - v0) * d0 <= 0)
    return int(below[-1] + 1) if below.size else 0


def _swept(v: np.ndarray) -> int:
    """Index by which ``v`` has reached both its 2 % and 98 % quantile levels (its size
    when it never does)."""
    lo, hi = np.quantile(v, [0.02, 0.98])
    low, high = np.flatnonzero(v <= lo), np.flatnonzero(v >= hi)
    return int(max(low[0], high[0])) if low.size and high.size else v.size


def _head_of(signals: Signals, m: int) -> Signals:
    """The first ``m`` samples of ``signals`` (every per-sample array), read-only."""
    n = np.asarray(signals.v).size

    def cut(a):
        if a is None:
            return None
        a = np.asarray(a)
        if a.shape != (n,):
            return a
        out = np.array(a[:m])
        out.flags.writeable = False
        return out

    extra = {k: cut(a) if isinstance(a, np.ndarray) else a for k, a in signals.extra.items()}
    return Signals(
        v=cut(signals.v), t_s=cut(signals.t_s), v_other=cut(signals.v_other),
        theta_other_deg=cut(signals.theta_other_deg), extra=extra,
    )  # fmt: skip


def _with_cycle(signals: Signals, k: int) -> Signals:
    """``signals`` with their first ``k`` samples replayed before them (this motor's
    input and every per-sample extra; times run back from ``t[0]``); the other motor's
    input and angle hold their first values meanwhile (:class:`InitialState`: its state
    is its own levels')."""
    if k <= 0:
        return signals
    v = np.asarray(signals.v)

    def rep(a):
        if a is None:
            return None
        a = np.asarray(a)
        return np.concatenate([a[:k], a]) if a.shape == v.shape else a

    def hold(a):
        if a is None:
            return None
        a = np.asarray(a)
        return np.concatenate([np.full(k, a[0], dtype=a.dtype), a]) if a.shape == v.shape else a

    t = None
    if signals.t_s is not None:
        t0 = np.asarray(signals.t_s, dtype=float)
        dt = float(np.median(np.diff(t0))) if t0.size > 1 else 1.0
        t = np.concatenate([t0[0] - dt * np.arange(k, 0, -1), t0])
    extra = {key: rep(a) if isinstance(a, np.ndarray) else a for key, a in signals.extra.items()}
    return Signals(
        v=rep(v), t_s=t, v_other=hold(signals.v_other),
        theta_other_deg=hold(signals.theta_other_deg), extra=extra,
    )  # fmt: skip


#: The pre-history's levels may lie beyond the recording's range by this fraction of
#: it (an input that went further before the recording started), on the side of zero
#: only when the input crosses zero.
LEVEL_MARGIN = 0.25


def level_bounds(v: np.ndarray) -> tuple[float, float]:
    """(lowest, highest) level of the pre-history (:class:`InitialState`): the input's
    range with zero, widened by :data:`LEVEL_MARGIN` of it (below zero only for an
    input that goes below zero: a one-sided input stays one-sided)."""
    v = np.asarray(v, dtype=float)
    lo, hi = min(float(v.min()), 0.0), max(float(v.max()), 0.0)
    pad = LEVEL_MARGIN * (hi - lo)
    return (lo - pad if float(v.min()) < 0 else lo), hi + pad


#: The input at rest (every operator relaxed): where a history of turning points begins.
ORIGIN = 0.0


def prehistory_step(v: np.ndarray) -> float:
    """Input step of the synthetic pre-history (:class:`InitialState`): the median
    non-zero step of ``v`` (its typical speed), or 1 % of its range."""
    v = np.asarray(v, dtype=float)
    steps = np.abs(np.diff(v))
    moving = steps[steps > 0]
    return float(np.median(moving)) if moving.size else float(np.ptp(v)) / 100


def _ramped(v: np.ndarray, levels, step: float) -> tuple[np.ndarray, int]:
    """(the input ``v`` after ramps through ``levels`` (a level or a sequence of them,
    the operators relaxed at the first) to ``v[0]`` in steps of about ``step``,
    read-only; the ramps' length). Equal consecutive levels add nothing.

    Relaxed at the first level is the state of an input that came there from rest
    (:data:`ORIGIN`) in one ramp: every play operator and slip element starts at its
    rest value clamped into its band there. The levels are so the turning points of a
    history from rest, and a first level at the rest adds nothing."""
    path = [float(u) for u in np.atleast_1d(levels)]
    path = [u for i, u in enumerate(path) if i == len(path) - 1 or u != path[i + 1]]
    parts = []
    for a, b in zip(path, [*path[1:], float(v[0])], strict=True):
        last = b == float(v[0]) and a == path[-1]
        k = int(np.clip(np.ceil(abs(b - a) / step), 2 if last else 1, MAX_PREHISTORY))
        parts.append(np.linspace(a, b, k + 1)[:-1])
    ramp = np.concatenate(parts)
    vv = np.concatenate([ramp, v])
    vv.flags.writeable = False  # the models keep what they derive from a frozen input
    return vv, ramp.size


def prehistory_signals(
    signals: Signals,
    v_from: float,
    step: float | None = None,
    cycle: int = 0,
    v_turn: float | None = None,
    other_levels: tuple[float, ...] | None = None,
    other_step: float | None = None,
    v_turn2: float | None = None,
    v_turn3: float | None = None,
) -> tuple[Signals, int]:
    """(``signals`` with the synthetic pre-history of :class:`InitialState` prepended,
    its length): the input ramps from ``v_from`` to ``v[0]`` in steps of ``step``
    (default :func:`prehistory_step` of ``v``), then (``cycle`` > 0) the recording's
    first ``cycle`` samples are replayed (this motor; the other holds its first value);
    the times run back from
    ``t[0]`` at the median interval; during the ramp the other motor's input and angle
    and every per-sample extra hold their first value. A model run on the result and
    cut by the length starts in the state the fit estimated
    (:meth:`~i2ris_calib.fitting.result.FitResult.predict` does this). ``v_turn``: an earlier turning point, the operators relaxed there and
    the input ramping to ``v_from`` first. ``other_levels`` ((o_turn2,) o_turn,
    o_from): the other motor's own pre-history, run first (this motor held where its
    ramps begin): relaxed at the first, ramping through the others to its first value in
    steps of
    ``other_step``; without them it holds its first value (relaxed there).
    ``v_turn2``: a turning point before ``v_turn`` (relaxed there, ramping to
    ``v_turn``, or to ``v_from`` when ``v_turn`` is None); ``v_turn3`` one before it."""
    v0 = np.asarray(signals.v, dtype=float)
    step = prehistory_step(v0) if step is None else step
    cycle = min(int(cycle), v0.size)
    signals = _with_cycle(signals, cycle)
    v = np.asarray(signals.v, dtype=float)
    levels = tuple(float(u) for u in (v_turn3, v_turn2, v_turn, v_from) if u is not None)
    vv, n_ramp = _ramped(v, levels, step)
    sig, n_pre = _ramp_padded(signals, vv, n_ramp)
    if other_levels is not None and signals.v_other is not None:
        sig, n_o = _other_first(sig, other_levels, other_step)
        n_pre += n_o
    return sig, n_pre + int(cycle)


def _other_first(signals: Signals, levels, step: float | None) -> tuple[Signals, int]:
    """(``signals`` with the other motor's pre-history through ``levels`` prepended,
    this motor (and every other per-sample array) held at its first value meanwhile;
    its length)."""
    vo = np.asarray(signals.v_other, dtype=float)
    step = prehistory_step(vo) if step is None else step
    ramp, n = _ramped(vo, tuple(float(x) for x in levels), step)
    v = np.asarray(signals.v)

    def hold(a):
        if a is None:
            return None
        a = np.asarray(a)
        if a.shape != v.shape:
            return a
        out = np.concatenate([np.full(n, a[0], dtype=a.dtype), a])
        out.flags.writeable = False
        return out

    t = None
    if signals.t_s is not None:
        t0 = np.asarray(signals.t_s, dtype=float)
        dt = float(np.median(np.diff(t0))) if t0.size > 1 else 1.0
        t = np.concatenate([t0[0] - dt * np.arange(n, 0, -1), t0])
    extra = {k: hold(a) if isinstance(a, np.ndarray) else a for k, a in signals.extra.items()}
    return (
        Signals(
            v=hold(v), t_s=t, v_other=ramp, theta_other_deg=hold(signals.theta_other_deg),
            extra=extra,
        ),
        n,
    )  # fmt: skip


def _ramp_padded(signals: Signals, vv: np.ndarray, n_pre: int) -> tuple[Signals, int]:
    """(``signals`` with the ramped input ``vv`` whose first ``n_pre`` samples are the
    ramp: every other per-sample array held at its first value there, times run back)."""
    v = np.asarray(signals.v, dtype=float)

    def pad(a):
        a = np.asarray(a)
        out = np.concatenate([np.full(n_pre, a[0], dtype=a.dtype), a])
        out.flags.writeable = False  # as the input: what the models derive is kept
        return out

    t = None
    if signals.t_s is not None:
        t0 = np.asarray(signals.t_s, dtype=float)
        dt = float(np.median(np.diff(t0))) if t0.size > 1 else 1.0
        t = np.concatenate([t0[0] - dt * np.arange(n_pre, 0, -1), t0])
    extra = {
        k: pad(a) if isinstance(a, np.ndarray) and a.shape == v.shape else a
        for k, a in signals.extra.items()
    }
    other = signals.v_other
    angle = signals.theta_other_deg
    return (
        Signals(
            v=vv,
            t_s=t,
            v_other=None if other is None else pad(other),
            theta_other_deg=None if angle is None else pad(angle),
            extra=extra,
        ),
        n_pre,
    )


class _FromLevel:
    """``model`` run after a synthetic pre-history: the operators relaxed at the level
    ``v_turn2`` (the third-last parameter), the input ramps to ``v_turn`` (the
    second-last), to ``v_from`` (the last) and then to ``v[0]`` (after the replayed
    first ``cycle`` samples, when given); the pre-history's outputs are dropped. Model
    protocol, plus the inner model's exact Jacobian and flag-point families when it has
    them."""

    TURN3 = "initial_state.v_turn3"
    TURN2 = "initial_state.v_turn2"
    TURN = "initial_state.v_turn"
    PARAM = "initial_state.v_from"
    OTHER_TURN2 = "initial_state.other_v_turn2"
    OTHER_TURN = "initial_state.other_v_turn"
    OTHER_FROM = "initial_state.other_v_from"

    def __init__(self, model: Model, v: np.ndarray, cycle: int = 0, v_other=None, n_own=3):
        self.inner = model
        #: Own levels at the end of the vector: ((v_turn3,) v_turn2,) v_turn, v_from.
        self.n_own = int(n_own)
        self.cycle = int(cycle)
        self.name = model.name
        v = np.asarray(v, dtype=float)
        lo, hi = level_bounds(v)
        other = ()
        self.other_step = None
        if v_other is not None and reads_other_state(model):
            vo = np.asarray(v_other, dtype=float)
            if vo.size and np.all(np.isfinite(vo)) and np.ptp(vo) > 0:
                olo, ohi = level_bounds(vo)
                other = (
                    Parameter(self.OTHER_TURN2, value=float(vo[0]), lower=olo, upper=ohi, unit="input",
                              doc="a turning point of the other motor's input before "
                                  "other_v_turn"),
                    Parameter(self.OTHER_TURN, value=float(vo[0]), lower=olo, upper=ohi, unit="input",
                              doc="an earlier turning point of the other motor's input"),
                    Parameter(self.OTHER_FROM, value=float(vo[0]), lower=olo, upper=ohi, unit="input",
                              doc="level the other motor's input came from"),
                )[max(3 - self.n_own, 0) :]  # as many as this motor's, at most three  # fmt: skip
                self.other_step = prehistory_step(vo)
        #: Number of level parameters at the end of the vector: (the other motor's
        #: as many as this one's,) then (v_turn2,) v_turn, v_from.
        self.n_other = len(other)
        self.levels = self.n_own + self.n_other
        self.parameters = (
            *model.parameters,
            *other,
            *[Parameter(self.TURN3, value=float(v[0]), lower=lo, upper=hi, unit="input",
                        doc="a turning point of the input before v_turn2"),
              Parameter(self.TURN2, value=float(v[0]), lower=lo, upper=hi, unit="input",
                        doc="a turning point of the input before v_turn")][4 - self.n_own :],
            Parameter(self.TURN, value=float(v[0]), lower=lo, upper=hi, unit="input",
                      doc="an earlier turning point of the input before the recording"),
            Parameter(self.PARAM, value=float(v[0]), lower=lo, upper=hi, unit="input",
                      doc="level the input came from before the recording"),
        )  # fmt: skip
        self.step = prehistory_step(v)
        self.jac_inner = _analytic_jacobian(model, "jacobian")
        self._head = None
        self.families_inner = _analytic_jacobian(model, "flag_point_families")
        self._cache: dict = {}

    def prehistory(self, signals: Signals, levels) -> tuple[Signals, int]:
        """(signals with the pre-history through ``levels`` (the last
        :attr:`levels` values: (the other motor's levels,) (v_turn2,) v_turn, v_from)
        prepended, its length)."""
        lv = tuple(float(x) for x in levels)
        own = lv[-self.n_own :]
        ut3, ut2, ut, u = own[0], own[-3] if self.n_own > 2 else own[0], own[-2], own[-1]
        other = lv[: self.n_other] if self.n_other else None
        key = (id(signals.v), *lv)
        hit = self._cache.get(key)
        if hit is not None and hit[0] is signals.v:  # the same array, not a reused id
            return hit[1]
        turn3 = ut3 if self.n_own > 3 else None
        out = prehistory_signals(
            signals, u, self.step, self.cycle, ut, other, self.other_step, ut2, turn3
        )
        if len(self._cache) > 4:
            self._cache.pop(next(iter(self._cache)))
        self._cache[key] = (signals.v, out)  # holds the array: its id is not reused
        return out

    def ramped(self, v: np.ndarray, levels) -> tuple[np.ndarray, int]:
        """(the input ``v`` after the ramps through ``levels`` and the replayed cycle,
        read-only; the pre-history's length)."""
        k = self.cycle
        vv, n = _ramped(np.concatenate([v[:k], v]) if k else v, levels, self.step)
        return vv, n + k

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        k = self.levels
        sig, n_pre = self.prehistory(signals, values[-k:])
        return np.asarray(self.inner.evaluate(sig, np.asarray(values[:-k], float)))[n_pre:]

    def level_output(self, signals: Signals, values: np.ndarray, idx: int = -1):
        """The output as a function of the level ``values[idx]`` alone (the other values
        held at ``values``), the same to the last bit as :meth:`evaluate`, for an inner model
        whose output is its ``own_output`` (of this axis's input only) plus its
        ``other_input_terms`` (of the other motor's input only): the pre-history holds
        the other input at its first value, which leaves those terms as they are
        without it, so they are computed once. None for other models."""
        terms_fn = _analytic_jacobian(self.inner, "other_input_terms")
        own_fn = _analytic_jacobian(self.inner, "own_output")
        vo = signals.v_other
        if terms_fn is None or own_fn is None or vo is None or not np.isfinite(vo[0]):
            return None
        at = idx - len(values) if idx >= 0 else idx
        if at < -self.n_own:
            return None  # the other motor's levels move its terms: no shortcut
        k = self.levels
        inner = np.asarray(values[:-k], float)
        levels = np.asarray(values[-self.n_own :], dtype=float).copy()
        # the other motor holds its first value during this motor's ramps and the
        # replayed cycle (its terms change only in its own pre-history, before them):
        # terms of [its pre-history | the cycle | the recording], from the recording on
        base = _with_cycle(signals, self.cycle)
        n_o = 0
        if self.n_other:
            base, n_o = _other_first(base, values[-k : -self.n_own], self.other_step)
        terms = [t[n_o + self.cycle :] for t in terms_fn(base, inner)]
        v = np.asarray(signals.v, dtype=float)

        def output(u: float) -> np.ndarray:
            lv = levels.copy()
            lv[at] = u
            vv, n_pre = self.ramped(v, lv)
            y = np.asarray(own_fn(Signals(v=vv), inner))[n_pre:]
            for term in terms:
                y += term
            return y

        return output

    def jacobian(self, signals, values, rows=None):
        """The inner model's exact columns and the levels' by forward differences
        of ``self.step / 2`` (the state after a ramp is continuous in where it began:
        LM moves the levels with the other parameters, the profile searches only
        explore)."""
        jac = self.inner_jacobian(signals, values, rows)
        rows = np.arange(np.asarray(signals.v).size) if rows is None else np.asarray(rows)
        values = np.asarray(values, dtype=float)
        head, m = self._opening(signals)
        near = rows < m
        base = self.evaluate(head, values)[rows[near]]
        cols = np.zeros((rows.size, self.levels))
        for c, j in enumerate(range(-self.levels, 0)):
            h = 0.5 * (self.step if j >= -self.n_own else self.other_step)
            trial = values.copy()
            trial[j] += h
            cols[near, c] = (self.evaluate(head, trial)[rows[near]] - base) / h
        return np.hstack([jac, cols])

    def _opening(self, signals: Signals) -> tuple[Signals, int]:
        """(the first samples of ``signals`` that the start state moves, their number):
        up to twice the index by which both inputs have reached both their 2 % and 98 %
        quantile levels (then every operator up to half the range has forgotten the
        start). The levels' Jacobian columns are differences over these samples, 0
        after them (a wider operator's trace is left to the profile searches, which
        use exact costs)."""
        if self._head is not None and self._head[0] is signals.v:
            return self._head[1], self._head[2]
        n = np.asarray(signals.v).size
        m = _swept(np.asarray(signals.v, dtype=float))
        vo = signals.v_other
        if vo is not None and np.all(np.isfinite(vo)) and np.ptp(vo) > 0:
            m = max(m, _swept(np.asarray(vo, dtype=float)))
        m = int(min(n, max(2 * m + 2, self.cycle + 2)))  # the replayed cycle is in it
        head = _head_of(signals, m)
        self._head = (signals.v, head, m)
        return head, m

    def inner_jacobian(self, signals, values, rows=None):
        """:meth:`jacobian` without the (zero) column of the profiled level."""
        k = self.levels
        sig, n_pre = self.prehistory(signals, values[-k:])
        rows = np.arange(np.asarray(signals.v).size) if rows is None else np.asarray(rows)
        return self.jac_inner(sig, np.asarray(values[:-k], float), rows=rows + n_pre)

    def flag_point_families(self, signals, values):
        k = self.levels
        sig, n_pre = self.prehistory(signals, values[-k:])
        return tuple(a[n_pre:] for a in self.families_inner(sig, np.asarray(values[:-k], float)))

    def with_values(self, values: np.ndarray) -> Model:
        return self.inner.with_values(np.asarray(values, dtype=float)[: -self.levels])


def state_levels(st: InitialState, k: int, n_own: int = 3) -> list[float]:
    """The ``k`` level values of :class:`_FromLevel` (of ``n_own`` own levels and
    ``k - n_own`` of the other motor's) for the start state ``st`` ((the other motor's
    (other_v_turn2,) other_v_turn, other_v_from,) ((v_turn3,) v_turn2,) v_turn, v_from)."""
    own = _staircase(st.v_turn3, st.v_turn2, st.v_turn, st.v_from)[-n_own:]
    if k == n_own:
        return own
    o_from = st.v0_other if st.other_v_from is None else st.other_v_from
    other = _staircase(st.other_v_turn2, st.other_v_turn, o_from)
    return [*other[len(other) - (k - n_own) :], *own]


def state_own_levels(st: InitialState) -> int:
    """Own levels of the :class:`_FromLevel` that runs the start state ``st``: four
    when it has ``v_turn3``, else three (fewer turning points are equal levels)."""
    return 4 if st.v_turn3 is not None else 3


def _staircase(*levels: float | None) -> list[float]:
    """The levels (earliest first, the last set) of a pre-history, a missing turning
    point equal to the next."""
    out = [float(levels[-1])]
    for u in reversed(levels[:-1]):
        out.insert(0, out[0] if u is None else float(u))
    return out


def innermost(model: Model) -> Model:
    """The model at the bottom of a stack of extensions (``model.nested()``, e.g.
    effects added by :func:`~i2ris_calib.hysteresis.effects.add_effect`); ``model``
    itself when it extends nothing. Its parameters come first in ``model``'s vector."""
    while callable(getattr(model, "nested", None)):
        model = model.nested()[0]
    return model
