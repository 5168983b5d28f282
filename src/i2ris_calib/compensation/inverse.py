"""Feedforward compensation: the commands that make a fitted hysteresis model follow a
target angle, by exact inversion of the stateful model (:mod:`.kernel`).

Everything here works in the *model's* convention: the input ``v`` the model sees
(a motion direction's input, >= 0, encoder counts for I2RIS) and its output angle
(deg; ``-theta`` for a ``"-"`` dataset). :mod:`i2ris_calib.commands.compensate` maps
signed encoder counts and angles to and from it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import i2ris_calib._display as _display
from i2ris_calib.compensation import kernel as K
from i2ris_calib.compensation._args import check_args
from i2ris_calib.compensation.safety import entry_ramp, find_spikes
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.effects import CATALOGUE, base_of, effects_of, model_values
from i2ris_calib.hysteresis.models import density, thresholds
from i2ris_calib.hysteresis.registry import KINDS, kind_of
from i2ris_calib.interrupts import deferred
from i2ris_calib.model import Signals

STATUS_NAMES = {
    K.STATUS_OK: "reached",
    K.STATUS_ABOVE: "above_range",
    K.STATUS_BELOW: "below_range",
    K.STATUS_RATE: "rate_limit",
    K.STATUS_GAP: "output_step",
    K.STATUS_DELAY: "within_delay",
}
"""Meaning of :attr:`CompensationResult.status`: ``above_range`` / ``below_range`` -
the target is beyond what the model reaches inside the allowed input range;
``rate_limit`` - the rate limit stops the command short; ``output_step`` - the target
lies inside a discontinuity of the model's output (the paper's EGPI step at ``v_f``,
or the reversal jump of the ``r = 0`` operator), the nearer side is taken;
``within_delay`` - the first ``delay_s`` seconds of a model with a time delay, which
no command can reach any more."""

SUPPORTED_EFFECTS = tuple(name for name, e in CATALOGUE.items() if e.compensated)

#: Per-sample flags of a result (:attr:`CompensationResult.flags`), in this order:
#: the status reasons (``rate_limit`` is called ``rate_limited`` here) and
#: ``spike_removed`` (an up-and-back command spike was replaced by holding the previous
#: command). The entry ramp's samples (before the target's first time) are ``entry``.
FLAG_NAMES = (
    "above_range", "below_range", "within_delay", "rate_limited", "output_step", "spike_removed",
)  # fmt: skip
_FLAG_CODES = {
    "above_range": K.STATUS_ABOVE,
    "below_range": K.STATUS_BELOW,
    "within_delay": K.STATUS_DELAY,
    "rate_limited": K.STATUS_RATE,
    "output_step": K.STATUS_GAP,
}
#: Rounds of spike repair (each one re-inverts with the spikes found held)
MAX_REPAIR_ROUNDS = 25


@dataclass(frozen=True)
class CompensationResult:
    """Commands for a target and what the model predicts for them.

    Attributes
    ----------
    commands : ndarray, shape (n,)
        Model input to send (input unit; whole multiples of ``quantum``).
    commands_real : ndarray, shape (n,)
        The best real-valued input at each sample, from the state the sent commands
        left (before quantisation).
    predicted_deg : ndarray, shape (n,)
        The model's output for ``commands`` (deg), evaluated by the forward model
        over the whole command sequence.
    target_deg : ndarray, shape (n,)
        The target (deg, model convention).
    status : ndarray of int8, shape (n,)
        0 = reached; see :data:`STATUS_NAMES`.
    t_s : ndarray, shape (n,) or None
        Sample times (s).
    kind : str
        Model kind (``gpi``, ``egpi``, ``egpi_c``, or ``<kind>+time_delay``).
    v_limits : tuple of float
        Allowed input range.
    max_rate : float
        Rate limit (input unit per s; ``inf`` = none).
    quantum : float
        Command resolution (0 = real-valued).
    tol_deg : float
        Output error (deg) that counts as meeting the target.
    delay_s : float
        Total delay of the model's time-delay effects; the target was inverted
        ``delay_s`` ahead.
    spike_removed : ndarray of bool, shape (n,)
        Samples where an up-and-back command spike of the inverse
        (:func:`~i2ris_calib.compensation.safety.find_spikes`) was replaced by holding
        the previous command.
    spikes_left : int
        Spikes still in ``commands`` after :data:`MAX_REPAIR_ROUNDS` repair rounds
        (0 unless the repair did not converge).
    entry_commands : ndarray, shape (m,)
        The rate-limited ramp from ``v_initial`` to ``commands[0]``, sent before the
        first target sample (empty without ``v_initial``, a rate limit, or when one
        step does).
    entry_t_s : ndarray, shape (m,)
        Its times (s): one target interval apart, ending one before ``t_s[0]``.
    entry_predicted_deg : ndarray, shape (m,)
        The model's output along the entry ramp (deg).
    history_commands : ndarray, shape (h,)
        ``v_history``: the inputs before the entry ramp the model state was carried
        through (empty without it).
    history_t_s : ndarray, shape (h,)
        Their times (s): one target interval apart, ending one before the entry ramp.
    history_predicted_deg : ndarray, shape (h,)
        The model's output along them (deg).
    """

    commands: np.ndarray
    commands_real: np.ndarray
    predicted_deg: np.ndarray
    target_deg: np.ndarray
    status: np.ndarray
    t_s: np.ndarray | None
    kind: str
    v_limits: tuple[float, float]
    max_rate: float
    quantum: float
    delay_s: float = 0.0
    tol_deg: float = 0.0
    spike_removed: np.ndarray | None = None
    spikes_left: int = 0
    entry_commands: np.ndarray = field(default_factory=lambda: np.zeros(0))
    entry_t_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    entry_predicted_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    history_commands: np.ndarray = field(default_factory=lambda: np.zeros(0))
    history_t_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    history_predicted_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def flags(self) -> dict[str, np.ndarray]:
        """Per-sample flags (:data:`FLAG_NAMES`) -> bool arrays, shape (n,)."""
        out = {name: self.status == code for name, code in _FLAG_CODES.items()}
        spikes = self.spike_removed
        out["spike_removed"] = np.zeros(self.status.size, bool) if spikes is None else spikes
        return {name: out[name] for name in FLAG_NAMES}

    def max_rate_seen(self) -> float:
        """Largest |command step| / interval over the entry ramp and the commands
        (input unit per s); 0 for fewer than two commands or no times."""
        if self.t_s is None:
            return 0.0
        u = np.concatenate((self.entry_commands, self.commands))
        t = np.concatenate((self.entry_t_s, self.t_s))
        if u.size < 2:
            return 0.0
        return float(np.max(np.abs(np.diff(u)) / np.diff(t)))

    @property
    def reachable(self) -> np.ndarray:
        """True where the real-valued inverse reached the target, shape (n,)."""
        return self.status == K.STATUS_OK

    @property
    def error_deg(self) -> np.ndarray:
        """``predicted - target`` (deg), shape (n,)."""
        return self.predicted_deg - self.target_deg

    def summary(self) -> dict:
        """Plain numbers for reports: RMSE and max |error| (all samples and reachable
        ones), unreachable counts by reason."""
        e = self.error_deg
        ok = self.reachable

        def rms(a):
            return float(np.sqrt(np.mean(a**2))) if a.size else float("nan")

        def mx(a):
            return float(np.max(np.abs(a))) if a.size else float("nan")

        return {
            "n_samples": int(e.size),
            "rmse_deg": rms(e),
            "max_abs_err_deg": mx(e),
            "rmse_reachable_deg": rms(e[ok]),
            "max_abs_err_reachable_deg": mx(e[ok]),
            "n_unreachable": int((~ok).sum()),
            "unreachable": {
                name: int((self.status == code).sum())
                for code, name in STATUS_NAMES.items()
                if code != K.STATUS_OK
            },
            "flags": {name: int(f.sum()) for name, f in self.flags.items()},
            "n_entry": int(self.entry_commands.size),
            "n_history": int(self.history_commands.size),
            "spikes_left": int(self.spikes_left),
            "max_command_rate_per_s": self.max_rate_seen(),
        }

    def __repr__(self) -> str:
        n = int(self.status.size)
        bad = int(np.sum(self.status != K.STATUS_OK))
        e = self.predicted_deg - self.target_deg
        rmse = float(np.sqrt(np.mean(e**2))) if n else float("nan")
        text = (
            f"<CompensationResult {self.kind}: {n} samples, RMSE {_display.num(rmse)} deg, "
            f"{bad} unreachable, inputs {_display.num(self.v_limits[0])}.."
            f"{_display.num(self.v_limits[1])}"
            + (f", {self.spikes_left} spikes left" if self.spikes_left else "")
            + ">"
        )
        return _display.clip(text)

    def _repr_html_(self) -> str:
        """Notebook display: the numbers of :meth:`summary`."""
        summ = self.summary()
        rows = [(k, v) for k, v in summ.items() if not isinstance(v, dict)]
        rows += [(f"unreachable: {k}", v) for k, v in summ["unreachable"].items()]
        rows += [(f"flag: {k}", v) for k, v in summ["flags"].items()]
        return _display.table(
            ("", ""), rows, f"<b>CompensationResult</b> {_display.esc(self.kind)}"
        )


def _base_and_delay(model) -> tuple[object, float]:
    """(GPI/EGPI base model, total delay in s) of a possibly extended model."""

    effects = effects_of(model)
    bad = sorted({name for name, _, _ in effects if name not in SUPPORTED_EFFECTS})
    if bad:
        raise CalibError(
            f"compensate cannot invert the effect(s) {', '.join(bad)}; supported: "
            f"{', '.join(SUPPORTED_EFFECTS)} (use the fitted egpi/egpi_c/gpi model instead)"
        )
    delay = float(sum(vals.get("tau_s", 0.0) for _, _, vals in effects))
    return base_of(model), delay


def kernel_params(model) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, float, float, float]:
    """(kind code, c, r, p, kappa, v_f, dead band) of a base model.

    GPI / EGPI kinds: ``c`` (6,) = a1..a6, ``r``, ``p`` (m,). The two-tendon GPI
    (``agpi``, and the own tendons of ``agpi_coupled``): ``c`` (9,) = the sides' a1..a4
    (``_p`` then ``_n``) and ``theta0``, ``r``, ``p`` (2 m,) = side p's then side n's
    (:data:`~.kernel.KIND_AGPI`)."""
    code = K.FAMILY_CODES.get(getattr(kind_of(model), "inverse", None))  # the registry's
    if code == K.KIND_AGPI:
        v = model.value_dict()
        cs, rs, ps = [], [], []
        for side in ("p", "n"):
            r_s = thresholds(v[f"r1_{side}"], v[f"rn_{side}"], int(model.n))
            rs.append(r_s)
            ps.append(density(r_s, v[f"lam_{side}"], v[f"sigma_{side}"]))
            cs += [v[f"{k}_{side}"] for k in ("a1", "a2", "a3", "a4")]
        c = np.array([*cs, v["theta0"]], dtype=float)
        return K.KIND_AGPI, c, np.concatenate(rs), np.concatenate(ps), 1.0, np.inf, 0.0
    if code is not None:
        v = model.value_dict()
        r = thresholds(v["r1"], v["rn"], int(model.n))
        p = density(r, v["lam"], v["sigma"])
    if code in (K.KIND_EGPI, K.KIND_EGPI_C):
        c = np.array([v[k] for k in ("a1", "a2", "a3", "a4", "a5", "a6")])
        return code, c, r, p, v["kappa"], v["v_f"], float(model.deadband_counts)
    if code == K.KIND_GPI:
        c = np.array([v["a1"], v["a2"], v["a3"], v["a4"], v["a3"], v["a4"]])
        return K.KIND_GPI, c, r, p, 1.0, np.inf, 0.0
    *names, last = (k.kind for k in KINDS if k.inverse)
    raise CalibError(
        f"compensate inverts {', '.join(names)} and {last} models (optionally with a time delay), "
        f"not '{getattr(model, 'name', type(model).__name__)}'"
    )


def coupling_params(model) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(c (9,), r, p (2 m,)) of a coupled model's coupling as a two-tendon GPI on the
    other motor's signed counts (:data:`~.kernel.KIND_AGPI`: side p = ``cp``, side n =
    ``cn``, ``theta0`` 0, the held signs folded into ``p``): its output is exactly the
    coupling :func:`coupling_deg` gives. None for a model without coupling."""
    base = base_of(model)
    if not is_coupled(base):
        return None
    v = base.value_dict()
    cs, rs, ps = [], [], []
    for side in ("cp", "cn"):
        r_s = thresholds(v[f"r1_{side}"], v[f"rn_{side}"], int(base.n))
        rs.append(r_s)
        ps.append(float(v[f"sign_{side}"]) * density(r_s, v[f"lam_{side}"], v[f"sigma_{side}"]))
        cs += [v[f"{k}_{side}"] for k in ("a1", "a2", "a3", "a4")]
    return np.array([*cs, 0.0], dtype=float), np.concatenate(rs), np.concatenate(ps)


def default_tol(code: int, c: np.ndarray, p: np.ndarray, quantum: float) -> float:
    """Half the angle (deg) of one ``quantum`` on the steepest envelope:
    ``0.5 quantum max(a1, a3) sum p`` (for the two-tendon GPI the steeper side's)."""
    if code == K.KIND_AGPI:
        m = p.size // 2
        return (
            0.5
            * quantum
            * max(
                max(abs(c[0]), abs(c[2])) * float(np.sum(p[:m])),
                max(abs(c[4]), abs(c[6])) * float(np.sum(p[m:])),
            )
        )
    return 0.5 * quantum * max(abs(c[0]), abs(c[2])) * float(np.sum(p))


def is_coupled(model) -> bool:
    """True for an invertible model that reads the other motor's input (its registry
    row ``coupled``: the coupling is inverted with its own tendons)."""
    info = kind_of(base_of(model))
    return bool(info is not None and info.inverse and info.coupled)


def coupling_deg(
    model,
    v_other: np.ndarray,
    v_other_initial: float | None = None,
    t_s: np.ndarray | None = None,
    v_other_history: np.ndarray | None = None,
) -> np.ndarray:
    """The part of a coupled model's output (deg), shape (n,), that the other motor's
    signed input ``v_other`` (shape (n,); preceded by ``v_other_initial`` when given,
    and before that by ``v_other_history``, its inputs since rest) contributes:
    additive and independent of this axis's own input, so a coupled model is inverted
    as its two-tendon GPI on ``target - coupling_deg``."""
    vo = np.asarray(v_other, dtype=float)
    pre = [] if v_other_history is None else [np.asarray(v_other_history, dtype=float)]
    if v_other_initial is not None:
        pre.append(np.array([float(v_other_initial)]))
    n_pre = sum(a.size for a in pre)
    vo = np.concatenate((*pre, vo))
    zero = np.zeros(vo.size)
    values = model_values(model)
    with_c = model.evaluate(Signals(v=zero, v_other=vo), values)
    without = model.evaluate(Signals(v=zero), values)
    out = with_c - without
    return out[n_pre:]


def _checked_target(target_deg, t_s) -> tuple[np.ndarray, np.ndarray | None]:
    """(target, times) as contiguous float arrays, checked: a non-empty finite 1-D
    target; times (optional) of its shape, finite and strictly increasing."""
    target = np.ascontiguousarray(target_deg, dtype=float)
    t = None if t_s is None else np.ascontiguousarray(t_s, dtype=float)
    if target.ndim != 1 or target.size == 0:
        raise CalibError("the target must be a non-empty 1-D array of angles (deg)")
    bad = np.flatnonzero(~np.isfinite(target))
    if bad.size:
        raise CalibError(
            f"the target has {bad.size} NaN/inf angle(s) (first at sample {bad[0]}); "
            "fill or remove them"
        )
    if t is not None:
        if t.shape != target.shape:
            raise CalibError(f"t_s has {t.size} samples, the target {target.size}")
        if not np.all(np.isfinite(t)):
            raise CalibError("the target's times contain NaN/inf")
        d = np.flatnonzero(np.diff(t) <= 0)
        if d.size:
            raise CalibError(
                f"the target's times must increase strictly; sample {d[0] + 1} "
                f"(t = {t[d[0] + 1]:g} s) does not"
            )
    return target, t


def history_state(code, c, r, p, kappa, vf, db, v_hist):
    """The inverse's state (``w`` (2, m), ``state``) the inputs ``v_hist`` (shape (h,))
    leave: the model's initial state at ``v_hist[0]``, then one step per input
    (:func:`~.kernel.start`, :func:`~.kernel.advance`: the update the inverse applies,
    also used by the online compensator's ``advance``)."""
    c, r, p = (np.ascontiguousarray(a, dtype=float) for a in (c, r, p))
    w = np.zeros((2, p.size))
    state = np.zeros(K.STATE_SIZE)
    v_hist = np.ascontiguousarray(v_hist, dtype=float)
    K.start(code, c, r, p, kappa, vf, db, float(v_hist[0]), True, w, state)
    K.advance(code, c, r, p, kappa, vf, db, v_hist[1:], w, state)
    return w, state


def _check_history(v_history, v_other_history, v_initial, lo, hi, coupled):
    """The history as a float array (or None), checked: 1-D, finite, inside
    ``v_limits``, ending at ``v_initial`` when both are given, the other motor's of the
    same length (one-line CalibError)."""
    if v_history is None:
        if v_other_history is not None:
            raise CalibError("compensate: v_other_history needs v_history (this motor's)")
        return None, None
    h = np.asarray(v_history, dtype=float)
    if h.ndim != 1 or h.size == 0 or not np.all(np.isfinite(h)):
        raise CalibError(
            f"compensate: v_history must be a non-empty 1-D array of finite inputs, got shape "
            f"{h.shape}"
        )
    out = np.flatnonzero((h < lo) | (h > hi))
    if out.size:
        raise CalibError(
            f"compensate: v_history[{out[0]}] = {h[out[0]]:g} is outside v_limits ({lo:g}, "
            f"{hi:g}): the model is not known there"
        )
    if v_initial is not None and float(v_initial) != float(h[-1]):
        raise CalibError(
            f"compensate: v_initial {float(v_initial):g} is not the history's last input "
            f"{h[-1]:g}; give one of them"
        )
    ho = None
    if v_other_history is not None:
        ho = np.asarray(v_other_history, dtype=float)
        if ho.shape != h.shape or not np.all(np.isfinite(ho)):
            raise CalibError(
                f"compensate: v_other_history must be {h.size} finite signed counts (as "
                f"v_history), got shape {ho.shape}"
            )
    elif coupled:
        raise CalibError(
            "compensate: a coupled model with v_history needs v_other_history (the other "
            "motor's inputs over the same samples)"
        )
    return h, ho


def _initial_inputs(hist, hist_o, v_initial, v_other_initial):
    """(this motor's, the other motor's input before the first sample): the history's
    last inputs when a history is given (the other's only where not given), else as
    given."""
    if hist is None:
        return v_initial, v_other_initial
    if hist_o is not None and v_other_initial is None:
        v_other_initial = float(hist_o[-1])
    return float(hist[-1]), v_other_initial


def _kernel_of(base) -> tuple:
    """The compiled inverse's model tuple (code, c, r, p, kappa, v_f, deadband) of
    ``base`` (:func:`~.kernel.kernel_params`), scalars as floats."""
    code, c, r, p, kappa, vf, db = kernel_params(base)
    return (code, c, r, p, float(kappa), float(vf), float(db))


def _other_along_ramp(vo: np.ndarray, v_other_initial, n_ramp: int) -> np.ndarray:
    """The other motor's inputs over the entry ramp (held at its start state, or its
    first target-time input) and the target's samples."""
    vo_first = vo[0] if v_other_initial is None else float(v_other_initial)
    return np.concatenate((np.full(n_ramp, vo_first), vo))


def compensate(
    model,
    target_deg: np.ndarray,
    t_s: np.ndarray | None = None,
    *,
    v_limits: tuple[float, float],
    max_rate: float | None = None,
    quantum: float = 1.0,
    v_initial: float | None = None,
    tol_deg: float | None = None,
    entry: bool = True,
    repair_spikes: bool = True,
    v_other: np.ndarray | None = None,
    v_other_initial: float | None = None,
    v_history: np.ndarray | None = None,
    v_other_history: np.ndarray | None = None,
) -> CompensationResult:
    """Commands that make ``model`` follow ``target_deg``: exact inversion, sample by sample.

    Parameters
    ----------
    model : GPIModel, I2RISEGPIModel, ContinuousEGPIModel, TwoTendonGPIModel,
            CoupledTwoTendonModel or EffectModel
        Fitted model (its current parameter values; the two-tendon kinds take the
        signed input of the axis); an extended model may carry
        ``time_delay`` effects (the target is then inverted ``tau`` ahead).
    target_deg : ndarray, shape (n,)
        Desired output angle (deg, the model's convention), finite.
    t_s : ndarray, shape (n,), optional
        Sample times (s), strictly increasing; needed for ``max_rate`` and delays.
    v_limits : (float, float)
        Allowed input range (input unit), e.g. the range the model was fitted on.
    max_rate : float, optional
        Largest |input change| per second (input unit/s).
    quantum : float
        Command resolution (1.0 = whole encoder counts; 0 = real-valued).
    v_initial : float, optional
        Input before the first sample (e.g. 0 at rest): the operators start from
        the model's initial state there and the first command is a normal step.
        Default: the first command itself sets the initial state.
    tol_deg : float, optional
        An output within ``tol_deg`` of the target meets it: such a sample is
        ``reached``, and among inputs that meet the target the one that keeps the
        motion direction and moves least is sent (no reversal for an error a count
        cannot resolve anyway). Default: 0 (numerical precision) for real-valued
        commands; half the angle of one ``quantum`` on the steepest envelope
        (``0.5 quantum max(a1, a3) sum p``) for whole counts.
    entry : bool
        With ``v_initial`` and ``max_rate``: the first target sample is one unlimited
        step from ``v_initial``, and a ramp at ``max_rate`` from ``v_initial`` to it is
        returned (``entry_commands``) to be sent before the target starts. False: the
        first sample is an ordinary rate-limited step (flagged while it lags).
    repair_spikes : bool
        Replace every up-and-back command spike
        (:func:`~i2ris_calib.compensation.safety.find_spikes`; a branch switch of the
        model that the next sample undoes) by holding the previous command, re-inverting
        from there (flag ``spike_removed``).
    v_other : ndarray, shape (n,), optional
        The other motor's signed commands (counts) at the target's samples: needed by a
        coupled model (``agpi_coupled``), whose coupling term they fix; its own tendons
        are then inverted on the target less that term (exact: the term does not depend
        on this axis's input).
    v_other_initial : float, optional
        The other motor's signed counts before the first sample (its start state).
    v_history : ndarray, shape (h,), optional
        The inputs the model went through before the entry ramp, from rest: the model
        starts in its initial state at ``v_history[0]`` and is stepped through the rest
        (a conditioning sweep that puts it into a known state, or the commands sent
        before), so the inversion starts from the state they leave, not from rest.
        ``v_initial`` is then its last input (given too, it must equal it). Inside
        ``v_limits``. The result's ``history_*`` fields give them back with the
        model's output along them (times one target interval apart, before the entry
        ramp).
    v_other_history : ndarray, shape (h,), optional
        The other motor's signed inputs over the same samples (a coupled model with
        ``v_history``).

    Returns
    -------
    CompensationResult
        ``predicted_deg`` is the forward model evaluated over the whole command
        sequence (from ``v_initial`` when given), so it is exactly what the model
        predicts for the commands sent.
    """
    check_args(model, target_deg, t_s, v_limits, max_rate, quantum, v_initial, tol_deg)
    target, t = _checked_target(target_deg, t_s)
    lo, hi, rate = _checked_limits(v_limits, max_rate, quantum, v_initial, t)
    base, delay = _base_and_delay(model)
    coupled = is_coupled(base)
    hist, hist_o = _check_history(v_history, v_other_history, v_initial, lo, hi, coupled)
    v_initial, v_other_initial = _initial_inputs(hist, hist_o, v_initial, v_other_initial)
    kernel = _kernel_of(base)
    tol_deg = _checked_tol(tol_deg, kernel[0], kernel[1], kernel[3], float(quantum))
    vo = _checked_other(base, v_other, target, delay) if coupled else None
    goal = _goal(base, target, t, delay, vo, v_other_initial, hist_o)
    v0 = _start_command(v_initial, quantum, lo, hi, hist is not None)
    has_init = v_initial is not None
    first_free = bool(entry and has_init and np.isfinite(rate))
    # from rest at v0, or from the state the history leaves
    start = None if hist is None else history_state(*kernel, hist)
    u, u_real, status, hold, spikes_left = _inverted_with_repair(
        kernel, goal, np.zeros_like(target) if t is None else t, lo, hi, rate,
        float(quantum), v0, has_init, float(tol_deg), first_free, start, repair_spikes,
    )  # fmt: skip
    ramp, ramp_t = _entry_commands(first_free, t, v0, float(u[0]), rate, float(quantum))
    status = _status_on_target(status, t, delay)
    hist_t = _history_times(hist, t, ramp_t)
    vo_all = None if not coupled else _other_along_ramp(vo, v_other_initial, ramp.size)
    hist_pred, both = _predicted(
        model, (hist, hist_t, hist_o), (ramp, ramp_t), (u, t), v0 if has_init else None,
        vo_all, v_other_initial,
    )  # fmt: skip
    return CompensationResult(
        commands=u,
        commands_real=u_real,
        predicted_deg=both[ramp.size :],
        target_deg=target,
        status=status,
        t_s=t,
        kind=base.name + ("+time_delay" if delay > 0 else ""),
        v_limits=(lo, hi),
        max_rate=rate,
        quantum=float(quantum),
        delay_s=delay,
        tol_deg=float(tol_deg),
        spike_removed=hold.copy(),
        spikes_left=spikes_left,
        entry_commands=ramp,
        entry_t_s=ramp_t,
        entry_predicted_deg=both[: ramp.size],
        history_commands=np.zeros(0) if hist is None else hist.copy(),
        history_t_s=hist_t,
        history_predicted_deg=hist_pred,
    )


def _checked_tol(tol_deg, code: int, c, p, quantum: float) -> float:
    """``tol_deg``, or the default of :func:`default_tol` when None; >= 0 and finite."""
    if tol_deg is None:
        tol_deg = default_tol(code, c, p, quantum)
    if not (tol_deg >= 0 and np.isfinite(tol_deg)):
        raise CalibError(f"tol_deg must be >= 0, got {tol_deg:g}")
    return tol_deg


def _goal(base, target: np.ndarray, t, delay: float, vo, vo_initial, vo_history) -> np.ndarray:
    """The angle (deg) the base model's own input must produce, shape (n,): the target
    ``delay`` s ahead, less a coupled model's coupling term (fixed by the other motor's
    commands ``vo``; None for an uncoupled model)."""
    if delay > 0 and t is None:
        raise CalibError("a model with a time delay needs the target's times (time_s)")
    goal = np.interp(t + delay, t, target) if delay > 0 else target
    if vo is None:
        return goal
    with deferred():
        return goal - coupling_deg(base, vo, vo_initial, v_other_history=vo_history)


def _start_command(v_initial, quantum: float, lo: float, hi: float, from_history: bool) -> float:
    """The input before the first sample: ``v_initial`` (0 when None), rounded to the
    command ``quantum`` and clipped into [lo, hi] unless a history sets it exactly."""
    v0 = 0.0 if v_initial is None else float(v_initial)
    if quantum > 0 and v_initial is not None and not from_history:
        v0 = float(np.clip(np.round(v0 / quantum) * quantum, lo, hi))
    return v0


def _entry_commands(first_free: bool, t, v0: float, u0: float, rate: float, quantum: float):
    """(ramp, ramp_t): the rate-limited entry from ``v0`` to the first command ``u0`` and
    its times (s), one target interval apart before ``t[0]``; empty without an entry."""
    if not (first_free and t.size > 1):
        return np.zeros(0), np.zeros(0)
    dt0 = float(t[1] - t[0])
    ramp = entry_ramp(v0, u0, rate, dt0, quantum)
    return ramp, t[0] - dt0 * np.arange(ramp.size, 0, -1)


def _status_on_target(status: np.ndarray, t, delay: float) -> np.ndarray:
    """Status codes on the target's samples, shape (n,): with a delay, command k serves
    the target at ``t_k + delay``, and samples no command reaches are STATUS_DELAY."""
    if delay <= 0:
        return status
    j = np.searchsorted(t, t - delay * (1 + 1e-12), side="right") - 1
    return np.where(j >= 0, status[np.clip(j, 0, None)], K.STATUS_DELAY).astype(np.int8)


def _predicted(model, history, entry, commands, v_initial, vo_all, vo_initial):
    """(history output, entry + target output) in deg: the forward model over the whole
    command sequence, so it is exactly what the model predicts for what is sent.

    ``history`` = (inputs, times, other motor's inputs), ``entry`` = (ramp, times),
    ``commands`` = (commands, target times); with a history the model starts from rest
    at its first input, else from ``v_initial`` (None: the first command)."""
    (hist, hist_t, hist_o), (ramp, ramp_t), (u, t) = history, entry, commands
    nh = 0 if hist is None else hist.size
    with deferred():  # compiled, returns arrays: a Ctrl-C is raised after it (interrupts.py)
        if nh:
            both = forward(
                model,
                np.concatenate((hist, ramp, u)),
                None if t is None else np.concatenate((hist_t, ramp_t, t)),
                None,
                v_other=None if vo_all is None else np.concatenate((hist_o, vo_all)),
            )
        else:
            both = forward(
                model,
                np.concatenate((ramp, u)),
                None if t is None else np.concatenate((ramp_t, t)),
                v_initial,
                v_other=vo_all,
                v_other_initial=vo_initial,
            )
    return both[:nh], both[nh:]


def checked_limits(v_limits, max_rate, quantum, who: str = "") -> tuple[float, float, float]:
    """(lo, hi, rate): the input range and the rate limit (input unit/s; inf for none),
    checked with the command quantum; a one-line CalibError starting with ``who``
    (e.g. ``"Compensator: yaw "``) otherwise. Shared by the batch and the online path."""
    lo, hi = (float(x) for x in v_limits)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise CalibError(f"{who}v_limits must be finite with lo < hi, got ({lo:g}, {hi:g})")
    rate = np.inf if max_rate is None else float(max_rate)
    if not rate > 0:
        raise CalibError(f"{who}max_counts_per_s must be > 0, got {rate:g}")
    if not (quantum >= 0 and np.isfinite(quantum)):
        raise CalibError(f"{who}quantum must be >= 0, got {quantum:g}")
    return lo, hi, rate


def _checked_limits(v_limits, max_rate, quantum, v_initial, t) -> tuple[float, float, float]:
    """:func:`checked_limits`, and a rate limit needs times, the initial input inside."""
    lo, hi, rate = checked_limits(v_limits, max_rate, quantum)
    if np.isfinite(rate) and t is None:
        raise CalibError("a rate limit needs the target's times (time_s)")
    if v_initial is not None and not lo <= float(v_initial) <= hi:
        raise CalibError(f"the initial input {v_initial:g} is outside v_limits ({lo:g}, {hi:g})")
    return lo, hi, rate


def _checked_other(base, v_other, target: np.ndarray, delay: float) -> np.ndarray:
    """The other motor's signed commands a coupled model needs, shape (n,) like the
    target, finite; one-line CalibError when missing, misshapen, or with a delay."""
    if v_other is None:
        raise CalibError(
            f"compensate: the {base.name} model needs the other motor's commands "
            "(v_other, signed counts per target sample): compensate both axes together"
        )
    vo = np.asarray(v_other, dtype=float)
    if vo.shape != target.shape or not np.all(np.isfinite(vo)):
        raise CalibError(
            f"compensate: v_other must be {target.size} finite signed counts (one per "
            f"target sample), got shape {vo.shape}"
        )
    if delay > 0:
        raise CalibError("compensate: a coupled model with a time delay is not inverted")
    return vo


def _inverted_with_repair(
    kernel, goal, tt, lo, hi, rate, quantum, v0, has_init, tol, first_free, start, repair
):
    """(commands, real-valued commands, status, held samples, spikes left) of the
    kernel inversion (``kernel``: :func:`kernel_params`' arrays), with every up-and-back
    spike (:func:`~i2ris_calib.compensation.safety.find_spikes`) held and re-inverted
    when ``repair``, for at most :data:`MAX_REPAIR_ROUNDS` rounds."""
    code, c, r, p, kappa, vf, db = kernel
    hold = np.zeros(goal.size, dtype=bool)
    spikes = np.zeros(0, dtype=int)
    resume = K.Resume()  # a repair round re-inverts only what its new holds change
    for _ in range(MAX_REPAIR_ROUNDS if repair else 1):
        u, u_real, y_model, status = K.invert(
            code, c, r, p, kappa, vf, db, goal, tt, lo, hi, rate, quantum, v0, has_init, tol,
            hold=hold, first_free=first_free, start_state=start, resume=resume,
        )  # fmt: skip
        spikes = find_spikes(u, y_model, goal, tol, hi - lo, quantum)
        new = spikes[~hold[spikes]]
        if not repair or new.size == 0:
            break
        hold[new] = True
        resume.changed = new
    spikes_left = int(spikes.size) if not repair else int((~hold[spikes]).sum())
    return u, u_real, status, hold, spikes_left


def _history_times(hist, t, ramp_t: np.ndarray) -> np.ndarray:
    """Times (s) of the history inputs ``hist`` (None: none), shape (nh,): one target
    interval apart, ending one interval before the entry ramp (or the first target
    sample)."""
    nh = 0 if hist is None else hist.size
    if not nh:
        return np.zeros(0)
    dt_h = float(t[1] - t[0]) if t is not None and t.size > 1 else 1.0
    first_t = ramp_t[0] if ramp_t.size else (t[0] if t is not None else 0.0)
    return first_t - dt_h * np.arange(nh, 0, -1)


def forward(
    model,
    v: np.ndarray,
    t_s: np.ndarray | None = None,
    v_initial: float | None = None,
    v_other: np.ndarray | None = None,
    v_other_initial: float | None = None,
):
    """The model's output (deg), shape (n,), for input ``v`` (shape (n,)), preceded by
    ``v_initial`` when given (that sample is dropped from the result). ``v_other``
    (shape (n,)): the other motor's signed input, for a coupled model (preceded by
    ``v_other_initial``, else by its first value, when ``v_initial`` is given)."""

    v = np.asarray(v, dtype=float)
    t = None if t_s is None else np.asarray(t_s, dtype=float)
    vo = None if v_other is None else np.asarray(v_other, dtype=float)
    if v_initial is not None:
        dt = float(t[1] - t[0]) if t is not None and t.size > 1 else 1.0
        v = np.concatenate(([float(v_initial)], v))
        t = None if t is None else np.concatenate(([t[0] - dt], t))
        if vo is not None:
            first = vo[0] if v_other_initial is None else float(v_other_initial)
            vo = np.concatenate(([first], vo))
    y = model.evaluate(Signals(v=v, t_s=t, v_other=vo), model_values(model))
    return y[1:] if v_initial is not None else y
