"""Online compensation: an :class:`OnlineInverse` a control loop calls once per cycle
(the public :class:`i2ris_calib.Compensator` is one, with its files).

The batch path (:func:`~i2ris_calib.compensation.inverse.compensate`) inverts a whole
target; a controller knows one target sample at a time. :class:`OnlineInverse` carries
the inverse's state from one call to the next and takes exactly the batch's step
(:func:`~i2ris_calib.compensation.kernel.step_one` runs the compiled
:func:`~i2ris_calib.compensation.kernel._step` the batch loop runs, and
:meth:`OnlineInverse.advance` the kernel's :func:`~i2ris_calib.compensation.kernel.advance`
the batch runs through a history), so the same target sampled the same way gives the
same commands as ``compensate(..., v_initial=start, entry=False, repair_spikes=False)``
(docs/compensate.md, "Online use"), for every kind the batch inverts:

* gpi, egpi, egpi_c, agpi;
* ``agpi_coupled`` (an axis that also reads the other motor's counts): its coupling is
  advanced with the other motor's command at each step and its own tendons inverted on
  the target less the coupling, as the batch does with ``v_other``; with both axes
  compensated the two commands are solved jointly at every step
  (:func:`~i2ris_calib.compensation.kernel.step_pair`);
* a model with a time delay ``tau``: the target a step is given is the angle wanted
  ``tau`` after it (the batch inverts ``interp(t + tau)`` of its target).

Everything a controller needs is in :meth:`OnlineInverse.to_dict` (plain numbers: model
kind and kernel parameters, limits, rate, state; schema :data:`SCHEMA`), which
:meth:`OnlineInverse.from_dict` restores without the model objects. Files are read and
written by :mod:`i2ris_calib.io.online`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

import i2ris_calib._display as _display
from i2ris_calib._validate import as_1d_float, as_real, check_instance
from i2ris_calib.compensation import kernel as K
from i2ris_calib.compensation.inverse import (
    STATUS_NAMES,
    _base_and_delay,
    checked_limits,
    coupling_params,
    default_tol,
    is_coupled,
    kernel_params,
)
from i2ris_calib.errors import CalibError

#: Schema of :meth:`OnlineInverse.to_dict` (the JSON a controller loads); version 2 adds
#: ``delay_s`` and ``coupling`` per axis (version 1 files, without them, still load)
SCHEMA = "i2ris-calib.compensator/2"
#: Schemas :meth:`OnlineInverse.from_dict` reads
SCHEMAS_READ = ("i2ris-calib.compensator/1", SCHEMA)
#: Kernel kind code <-> name in the JSON (the inverse families of the registry)
KIND_NAMES = {code: family for family, code in K.FAMILY_CODES.items()}
_KIND_CODES = {v: k for k, v in KIND_NAMES.items()}
AXES = ("yaw", "pitch")
_OTHER = {"yaw": "pitch", "pitch": "yaw"}
#: Gauss-Seidel rounds of a joint step of two coupled axes (kernel.step_pair)
JOINT_ROUNDS = 8
#: Status code -> the flag of a step (as the batch's ``flags`` names them); reached: none
STEP_FLAGS = {
    K.STATUS_OK: (),
    K.STATUS_ABOVE: ("above_range",),
    K.STATUS_BELOW: ("below_range",),
    K.STATUS_RATE: ("rate_limited",),
    K.STATUS_GAP: ("output_step",),
    K.STATUS_DELAY: ("within_delay",),
}
#: Flag of a joint step whose two commands did not settle in :data:`JOINT_ROUNDS`
UNSETTLED = "coupling_unsettled"


class AxisCommand(NamedTuple):
    """One axis's result of :meth:`OnlineInverse.step`.

    Attributes
    ----------
    counts : float
        Signed encoder counts to send (whole counts; the robot's sign).
    predicted_deg : float
        The model's angle after this command (deg, robot's sign; with a time delay the
        angle ``delay_s`` later, which this command serves).
    status : int
        0 = target reached, else a :data:`~i2ris_calib.compensation.inverse.STATUS_NAMES` code.
    flags : tuple of str
        ``()`` when reached, else one of ``above_range``, ``below_range``,
        ``rate_limited``, ``output_step``; plus ``coupling_unsettled`` when the joint
        step of two coupled axes did not settle (:data:`JOINT_ROUNDS`).
    """

    counts: float
    predicted_deg: float
    status: int
    flags: tuple[str, ...]


@dataclass(frozen=True)
class AxisState:
    """The inverse's state of one axis after a step (all in the model's convention:
    the input the model sees, its output angle; ``sign`` maps them to the robot's).

    Attributes
    ----------
    operators : tuple of tuple of float
        Play-operator states ``w`` (deg), two rows of ``m`` (row 1 only used by the
        paper EGPI; the two-tendon GPI's row 0 holds side p then side n).
    direction : int
        Motion direction ``v'`` (+1 loading, -1 unloading).
    anchor : float
        Input where ``v'`` last turned (dead band reference, input unit).
    last_input : float
        The last command (model convention, input unit).
    last_output_deg : float
        The model's output after it (deg, model convention; a coupled model's own
        tendons, without the coupling).
    init : bool
        True: no command yet and no start state (the first command sets the state).
    last_move_s : float
        Time of the last command change (s; for a rate limit below one count per step).
    time_s : float
        Time of the last command (s; 0 at the start state).
    coupling_operators : tuple of float or None
        A coupled axis: the coupling's operator states (side p then side n of the
        other motor's input, ``2 mc``); None otherwise.
    other_counts : float or None
        A coupled axis: the other motor's last signed counts the coupling saw.
    coupling_deg : float
        A coupled axis: the coupling's angle after them (deg, model convention).
    """

    operators: tuple[tuple[float, ...], ...]
    direction: int
    anchor: float
    last_input: float
    last_output_deg: float
    init: bool
    last_move_s: float
    time_s: float
    coupling_operators: tuple[float, ...] | None = None
    other_counts: float | None = None
    coupling_deg: float = 0.0


class _Axis:
    """One axis's compiled inverse: kernel arrays, limits, state (mutable, private)."""

    __slots__ = ("name", "code", "c", "r", "p", "cfg", "w", "state", "out", "sign", "start",
                 "params", "kind", "prm", "mem", "delay", "coupling", "other_start", "wc",
                 "cstate")  # fmt: skip

    def __init__(self, name, kind, code, c, r, p, cfg, sign, start, params, delay=0.0,
                 coupling=None, other_start=0.0):  # fmt: skip
        self.name = name
        self.kind = kind
        self.code = int(code)
        self.c, self.r, self.p, self.cfg = (
            np.ascontiguousarray(a, dtype=float) for a in (c, r, p, cfg)
        )
        self.sign = float(sign)
        self.start = float(start)
        self.params = dict(params)
        self.delay = float(delay)
        self.other_start = float(other_start)
        if self.p.size != self.r.size or self.c.size != (9 if self.code == K.KIND_AGPI else 6):
            raise CalibError(f"{name}: kernel arrays c, r, p do not fit the kind {kind}")
        if self.sign not in (-1.0, 1.0) or not (math.isfinite(self.delay) and self.delay >= 0):
            raise CalibError(f"{name}: sign must be +1 or -1 and delay_s a time >= 0")
        if coupling is not None:
            coupling = tuple(np.ascontiguousarray(a, dtype=float).ravel() for a in coupling)
            if coupling[0].size != 9 or coupling[1].size != coupling[2].size:
                raise CalibError(f"{name}: coupling arrays c, r, p do not fit a two-tendon GPI")
            if self.delay > 0:
                raise CalibError(f"{name}: a coupled model with a time delay is not inverted")
        _check_axis_values(name, self.c, self.r, self.p, self.cfg, self.sign * self.start,
                           coupling, self.other_start, self.params)  # fmt: skip
        self.coupling = coupling
        self.prm, self.mem = K.pack(self.c, self.r, self.p, self.cfg, self.sign, coupling)
        self.w, self.state, self.out, self.wc, self.cstate = K.views(self.prm, self.mem)
        self.reset()

    def reset(self):
        self.mem[:] = 0.0
        kappa, vf, db = self.cfg[:3]
        K.start(self.code, self.c, self.r, self.p, kappa, vf, db, self.start * self.sign, True,
                self.w, self.state)  # fmt: skip
        if self.coupling is not None:
            K.start(K.KIND_AGPI, *self.coupling, 1.0, math.inf, 0.0, self.other_start, True,
                    self.wc, self.cstate)  # fmt: skip
        self.out[0] = self.start * self.sign
        self.out[2] = self.state[3] + (0.0 if self.cstate is None else self.cstate[3])

    def command(self) -> AxisCommand:
        """The last step's result (robot's sign)."""
        u, _, y, st, _, rounds = self.out.tolist()
        st = int(st)
        flags = STEP_FLAGS[st] if rounds >= 0 else STEP_FLAGS[st] + (UNSETTLED,)
        return AxisCommand(self.sign * u + 0.0, self.sign * y, st, flags)

    def advance(self, v_model: np.ndarray, v_other: np.ndarray | None, dt: float) -> None:
        """Carry the state through inputs already sent (model convention; the other
        motor's signed counts for a coupled axis), one ``dt`` apart."""
        kappa, vf, db = self.cfg[:3]
        if v_model.size == 0:
            return
        K.advance(self.code, self.c, self.r, self.p, kappa, vf, db, v_model, self.w,
                  self.state[: K.STATE_SIZE])  # fmt: skip
        if self.coupling is not None:
            K.advance(K.KIND_AGPI, *self.coupling, 1.0, math.inf, 0.0, v_other, self.wc,
                      self.cstate)  # fmt: skip
        self.state[K.STATE_SIZE] += v_model.size * dt
        self.state[5] = self.state[K.STATE_SIZE]  # the last command counts as a move
        self.out[0] = v_model[-1]
        self.out[2] = self.state[3] + (0.0 if self.cstate is None else self.cstate[3])

    def get(self) -> AxisState:
        s = self.state
        cs = self.cstate
        return AxisState(
            operators=tuple(tuple(float(x) for x in row) for row in self.w),
            direction=int(s[0]), anchor=float(s[1]), last_input=float(s[2]),
            last_output_deg=float(s[3]), init=bool(s[4]), last_move_s=float(s[5]),
            time_s=float(s[K.STATE_SIZE]),
            coupling_operators=None if cs is None else tuple(float(x) for x in self.wc[0]),
            other_counts=None if cs is None else float(cs[2]),
            coupling_deg=0.0 if cs is None else float(cs[3]),
        )  # fmt: skip

    def set(self, st: AxisState) -> None:
        w = np.asarray(st.operators, dtype=float)
        if w.shape != self.w.shape or not np.all(np.isfinite(w)):
            raise CalibError(
                f"{self.name}: state operators must be finite, shape {self.w.shape}, got {w.shape}"
            )
        vals = (st.direction, st.anchor, st.last_input, st.last_output_deg, float(st.init),
                st.last_move_s, st.time_s)  # fmt: skip
        if not all(math.isfinite(float(x)) for x in vals) or int(st.direction) not in (-1, 1):
            raise CalibError(f"{self.name}: state values must be finite, direction +1 or -1")
        lo, hi = float(self.cfg[3]), float(self.cfg[4])
        if not lo <= float(st.last_input) <= hi:
            raise CalibError(
                f"{self.name}: state last_input {float(st.last_input):g} is outside the input "
                f"range {lo:g}..{hi:g} (the model's convention): the model is not known there"
            )
        if self.coupling is not None:
            wc = np.asarray(
                st.coupling_operators if st.coupling_operators is not None else [], dtype=float
            )
            cvals = (st.other_counts, st.coupling_deg)
            if (
                wc.shape != (self.wc.shape[1],)
                or not np.all(np.isfinite(wc))
                or any(x is None or not math.isfinite(float(x)) for x in cvals)
            ):
                raise CalibError(
                    f"{self.name}: a coupled axis's state needs coupling_operators "
                    f"({self.wc.shape[1]} finite), other_counts and coupling_deg"
                )
            self.wc[0] = wc
            self.wc[1] = 0.0
            oc = float(st.other_counts)
            self.cstate[:] = [1.0, oc, oc, float(st.coupling_deg), 0.0, 0.0]
        self.w[:] = w
        self.state[:] = [float(x) for x in vals]
        self.out[0] = self.state[2]
        self.out[2] = self.state[3] + (0.0 if self.cstate is None else self.cstate[3])


def _axis_from_model(name, model, v_limits, sign, max_rate, start, quantum, tol_deg,
                     other_start=0.0, exact_start=False):  # fmt: skip
    base, delay = _base_and_delay(model)
    coupling = coupling_params(base) if is_coupled(base) else None
    if delay > 0 and coupling is not None:
        raise CalibError(
            f"Compensator: the {name} model is coupled and has a time delay; neither the "
            "batch nor the online compensator inverts that"
        )
    code, c, r, p, kappa, vf, db = kernel_params(base)
    lo, hi, rate = checked_limits(v_limits, max_rate, quantum, f"Compensator: {name} ")
    v0 = float(sign) * float(start)
    if quantum > 0 and not exact_start:
        v0 = float(np.round(v0 / quantum) * quantum)
    if not lo <= v0 <= hi:
        raise CalibError(
            f"Compensator: {name} start counts {start:g} are outside the input range "
            f"{min(sign * lo, sign * hi):g}..{max(sign * lo, sign * hi):g}"
        )
    tol = default_tol(code, c, p, float(quantum)) if tol_deg is None else float(tol_deg)
    cfg = np.array([kappa, vf, db, lo, hi, rate, quantum, tol], dtype=float)
    params = {k: float(x) for k, x in base.value_dict().items()}
    return _Axis(name, base.name, code, c, r, p, cfg, sign, sign * v0, params, delay=delay,
                 coupling=coupling, other_start=float(other_start))  # fmt: skip


class OnlineInverse:
    """Online feedforward compensation: one target sample in, one command per axis out.

    Parameters
    ----------
    models : dict
        Axis (``"yaw"``, ``"pitch"``) -> fitted model (gpi, egpi, egpi_c, agpi,
        agpi_coupled, or one of them with a time delay; the model's convention: input
        >= 0 of a motion direction, or the signed input for the two-tendon kinds).
    v_limits : dict
        Axis -> (lo, hi): allowed input (model convention, counts), e.g. the fitted range.
    signs : dict, optional
        Axis -> +1 or -1: robot's signed counts and angle = sign x the model's (-1 for a
        ``-`` dataset). Default +1.
    max_counts_per_s : dict or float, optional
        Rate limit (counts/s) per axis or for all; None or ``inf``: none.
    start_counts : dict or float
        Signed counts the motor rests at before the first step (robot's sign); a
        coupled axis compensated alone also takes its other motor's start counts here.
    quantum : float
        Command resolution (1 = whole counts).
    tol_deg : float, optional
        As :func:`~i2ris_calib.compensation.inverse.compensate` (default from the model).
    history : dict, optional
        Axis -> signed counts already sent (robot's sign), oldest first, one ``dt_s``
        apart: the model starts at rest at each motor's first value and is carried
        through the rest (:meth:`advance`), as ``compensate(v_history=...,
        v_other_history=...)``; replaces ``start_counts``. A conditioning sweep
        (:func:`~i2ris_calib.compensation.safety.conditioning_sweep`) is one.
    dt_s : float
        Interval of the ``history`` samples (s).

    Notes
    -----
    ``step`` gives the commands ``compensate(model, target, t, v_limits=...,
    max_rate=..., v_initial=start, entry=False, repair_spikes=False)`` gives for the
    same samples (to 1e-9): the rate limit moves the command from the start state (no
    separate entry ramp), and there is no spike repair (it needs the next sample).
    A coupled axis: ``v_other`` = the other motor's commands (those this compensator
    sends when it compensates both axes, else ``step(other_counts=...)``). A delayed
    axis: the batch's target ``tau`` ahead (the step's target is the angle wanted at
    its time plus :attr:`delays`).
    """

    def __init__(self, models, v_limits, signs=None, max_counts_per_s=None, start_counts=0.0,
                 quantum=1.0, tol_deg=None, history=None, dt_s=0.01):  # fmt: skip
        if not isinstance(models, dict) or not models or any(a not in AXES for a in models):
            raise CalibError("Compensator: models must be a dict axis ('yaw', 'pitch') -> model")
        hist = None
        if history is not None:
            hist = _checked_history(history, models)
            start_counts = {a: float(h[0]) for a, h in hist.items()}
        self._axes: dict[str, _Axis] = {}
        for name, model in models.items():

            def per(x, default, name=name):
                return (
                    x.get(name, default) if isinstance(x, dict) else (default if x is None else x)
                )

            if name not in v_limits:
                raise CalibError(f"Compensator: no v_limits for {name}")
            self._axes[name] = _axis_from_model(
                name, model, v_limits[name], float(per(signs, 1.0)),
                per(max_counts_per_s, None), float(per(start_counts, 0.0)), float(quantum),
                tol_deg, other_start=float(per(start_counts, 0.0, _OTHER[name])),
                exact_start=hist is not None,
            )  # fmt: skip
        self._plan()
        self._start_state = None
        if hist is not None:
            self.advance({a: h[1:] for a, h in hist.items()}, dt_s=dt_s)
            self._start_state = self.state

    @classmethod
    def _from_axes(cls, axes: dict[str, _Axis]) -> OnlineInverse:
        obj = cls.__new__(cls)
        obj._axes = axes
        obj._start_state = None
        obj._plan()
        return obj

    @property
    def axes(self) -> tuple[str, ...]:
        """The compensated axes."""
        return tuple(self._axes)

    @property
    def delays(self) -> dict[str, float]:
        """Axis -> time delay of its model (s; 0 without): a step's target for that axis
        is the angle wanted this long after the step."""
        return {name: ax.delay for name, ax in self._axes.items()}

    @property
    def coupled(self) -> dict[str, str | None]:
        """Axis -> the other motor its model reads (``"pitch"`` / ``"yaw"``), or None."""
        return {n: (_OTHER[n] if a.coupling is not None else None) for n, a in self._axes.items()}

    def step(
        self,
        target_yaw_deg: float | None = None,
        target_pitch_deg: float | None = None,
        dt_s: float = 0.01,
        other_counts: float | None = None,
    ) -> dict[str, AxisCommand]:
        """Commands for one target sample, ``dt_s`` seconds after the previous step
        (or the start state).

        Parameters
        ----------
        target_yaw_deg, target_pitch_deg : float
            Desired angle (deg, robot's sign) of every compensated axis; for an axis
            with a time delay the angle wanted :attr:`delays` seconds after this step.
        dt_s : float
            Time since the previous step (s), > 0.
        other_counts : float, optional
            A coupled axis compensated alone: the other motor's signed counts sent at
            this step (its coupling's input).

        Returns
        -------
        dict
            Axis -> :class:`AxisCommand` (signed counts, predicted angle, status, flags).
        """
        dt_s = _number("Compensator.step", "dt_s", dt_s)
        if not 0 < dt_s < math.inf:
            raise CalibError(f"Compensator.step: dt_s must be a time > 0 s, got {dt_s!r}")
        if self._pair:
            a, b = self._items[0][1], self._items[1][1]
            ty, tp = self._target("yaw", target_yaw_deg), self._target("pitch", target_pitch_deg)
            K.step_pair(a.code, a.prm, a.mem, b.code, b.prm, b.mem, a.sign * ty, b.sign * tp,
                        dt_s, JOINT_ROUNDS)  # fmt: skip
        else:
            for name, ax in self._items:
                tk = self._target(name, target_yaw_deg if name == "yaw" else target_pitch_deg)
                vo = 0.0
                if ax.coupling is not None:
                    if other_counts is None or not math.isfinite(
                        _number("Compensator.step", "other_counts", other_counts)
                    ):
                        raise CalibError(
                            f"Compensator.step: the {name} model reads the {_OTHER[name]} "
                            f"motor: give other_counts (its signed counts at this step), got "
                            f"{other_counts!r}"
                        )
                    vo = float(other_counts)
                K.step_one(ax.code, ax.prm, ax.mem, ax.sign * tk, dt_s, vo)
        return {name: ax.command() for name, ax in self._items}

    @staticmethod
    def _target(name, tk):
        if tk is None or not math.isfinite(_number("Compensator.step", f"target_{name}_deg", tk)):
            raise CalibError(f"Compensator.step: give a finite target_{name}_deg, got {tk!r}")
        return float(tk)

    def _plan(self) -> None:
        """The axes in order and whether a step solves them jointly (one compiled call)."""
        axes = self._axes
        self._items = tuple((n, axes[n]) for n in AXES if n in axes)
        self._pair = len(axes) == 2 and any(a.coupling is not None for a in axes.values())

    def advance(self, commands: dict, dt_s: float = 0.01) -> None:
        """Carry the model state through commands already sent (no inversion): axis ->
        signed counts (robot's sign), oldest first, one ``dt_s`` apart, every
        compensated axis (and the other motor of a coupled axis compensated alone) the
        same number. The kernel's :func:`~i2ris_calib.compensation.kernel.advance`,
        the update the batch applies to ``compensate(v_history=...)``; the time moves
        on by ``dt_s`` per sample and the last one counts as a move."""
        dt_s = _number("Compensator.advance", "dt_s", dt_s)
        if not dt_s > 0 or dt_s == math.inf:
            raise CalibError(f"Compensator.advance: dt_s must be a time > 0 s, got {dt_s!r}")
        need = set(self._axes) | {
            _OTHER[n] for n, a in self._axes.items() if a.coupling is not None
        }
        if not isinstance(commands, dict) or not need <= set(commands):
            raise CalibError(
                f"Compensator.advance: give the counts of {', '.join(sorted(need))} (a dict)"
            )
        arrs = {}
        for name in sorted(need):
            v = as_1d_float("Compensator.advance", f"commands['{name}']", commands[name],
                            hint="give the signed counts sent, all finite")  # fmt: skip
            arrs[name] = np.ascontiguousarray(v)
        sizes = {v.size for v in arrs.values()}
        if len(sizes) != 1:
            raise CalibError("Compensator.advance: every motor needs the same number of counts")
        for name, ax in self._axes.items():
            vm = ax.sign * arrs[name]
            lo, hi = ax.cfg[3], ax.cfg[4]
            bad = np.flatnonzero((vm < lo) | (vm > hi))
            if bad.size:
                raise CalibError(
                    f"Compensator.advance: {name} counts[{bad[0]}] = {arrs[name][bad[0]]:g} are "
                    "outside the input range: the model is not known there"
                )
        for name, ax in self._axes.items():
            vo = arrs[_OTHER[name]] if ax.coupling is not None else None
            ax.advance(np.ascontiguousarray(ax.sign * arrs[name]), vo, float(dt_s))

    @property
    def state(self) -> dict[str, AxisState]:
        """Axis -> :class:`AxisState` (a copy: a later step does not change it)."""
        return {name: ax.get() for name, ax in self._axes.items()}

    def reset(self, state: dict[str, AxisState] | None = None) -> None:
        """Back to the start state (at rest at the start counts; after the constructor's
        ``history`` when it had one; a compensator read from JSON: at rest at its start
        counts), or to ``state`` (as :attr:`state` returned it, e.g. saved before a
        pause)."""
        if state is None and self._start_state is not None:
            state = self._start_state
        if state is None:
            for ax in self._axes.values():
                ax.reset()
            return
        if not isinstance(state, dict) or set(state) != set(self._axes):
            raise CalibError(f"Compensator.reset: give a state of the axes {', '.join(self._axes)}")
        for name, st in state.items():
            check_instance("Compensator.reset", f"state['{name}']", st, AxisState,
                           hint="as Compensator.state returned it")  # fmt: skip
        for name, st in state.items():
            try:
                self._axes[name].set(st)
            except CalibError as exc:
                raise CalibError(f"Compensator.reset: {exc}") from None
            except (TypeError, ValueError) as exc:
                raise CalibError(
                    f"Compensator.reset: state['{name}'] has a value that is not a number "
                    f"({exc}); give a state as Compensator.state returned it"
                ) from None

    def to_dict(self) -> dict:
        """Everything a controller needs, in plain numbers (docs/compensate.md, "Online
        use"): per axis the model kind and its parameters, the kernel arrays (``c``,
        ``r``, ``p``), limits, rate, resolution, tolerance, sign, start counts, time
        delay, coupling (or null) and the current state."""
        axes = {name: _axis_dict(name, ax) for name, ax in self._axes.items()}
        return {"schema": SCHEMA, "statuses": {str(k): v for k, v in STATUS_NAMES.items()},
                "joint_rounds": JOINT_ROUNDS, "axes": axes}  # fmt: skip

    @classmethod
    def from_dict(cls, doc: dict) -> OnlineInverse:
        """The compensator :meth:`to_dict` described (no model objects needed; schema
        version 1 or 2); CalibError naming the key for a document that is not one."""
        if not isinstance(doc, dict) or doc.get("schema") not in SCHEMAS_READ:
            raise CalibError(f"not a compensator document (schema '{SCHEMA}' expected)")
        axes = {}
        for name, a in (doc.get("axes") or {}).items():
            try:
                if name not in AXES:
                    raise KeyError("axes")
                code = _KIND_CODES[a["kernel_kind"]]
                vf = math.inf if a["v_f"] is None else float(a["v_f"])
                rate = math.inf if a["max_counts_per_s"] is None else float(a["max_counts_per_s"])
                cfg = [float(a["kappa"]), vf, float(a["deadband_counts"]), *map(float, a["v_limits"]),
                       rate, float(a["quantum"]), float(a["tol_deg"])]  # fmt: skip
                cpl = a.get("coupling")
                coupling = None if cpl is None else (cpl["c"], cpl["r"], cpl["p"])
                if cpl is not None and cpl["other_axis"] != _OTHER[name]:
                    raise ValueError("coupling.other_axis")
                ax = _Axis(name, str(a["model"]), code, a["c"], a["r"], a["p"], cfg,
                           float(a["sign"]), float(a["start_counts"]), a["params"],
                           delay=float(a.get("delay_s") or 0.0), coupling=coupling,
                           other_start=0.0 if cpl is None else float(cpl["other_start_counts"]),
                           )  # fmt: skip
                s = a["state"]
                sc = s.get("coupling") if cpl is not None else None
                if cpl is not None and sc is None:
                    raise KeyError("state.coupling")
                ax.set(AxisState(
                    operators=tuple(tuple(row) for row in s["operators"]),
                    direction=int(s["direction"]), anchor=float(s["anchor"]),
                    last_input=float(s["last_input"]),
                    last_output_deg=float(s["last_output_deg"]), init=bool(s["init"]),
                    last_move_s=float(s["last_move_s"]), time_s=float(s["time_s"]),
                    coupling_operators=None if sc is None else tuple(sc["operators"]),
                    other_counts=None if sc is None else float(sc["other_counts"]),
                    coupling_deg=0.0 if sc is None else float(sc["coupling_deg"]),
                ))  # fmt: skip
            except CalibError as exc:
                raise CalibError(f"compensator document: axis '{name}': {exc}") from None
            except (KeyError, TypeError, ValueError) as exc:
                raise CalibError(
                    f"compensator document: axis '{name}': missing or bad {exc}"
                ) from None
            axes[name] = ax
        if not axes:
            raise CalibError("compensator document: no axes")
        return cls._from_axes(axes)

    def __repr__(self) -> str:
        parts = [
            f"{n} {a.kind} at {a.sign * a.state[2] + 0.0:g} counts" for n, a in self._axes.items()
        ]
        return f"<Compensator {', '.join(parts)}>"

    def _repr_html_(self) -> str:
        """Notebook display: per axis its model kind, sign, input limits (the model's
        convention), rate limit, delay, the other motor it reads, and its state (the last
        command and angle in the robot's sign, the time stepped)."""
        rows = []
        for name, a in self._axes.items():
            lo, hi, rate = (float(x) for x in a.cfg[3:6])
            rows.append((
                name, a.kind, f"{a.sign:+g}", f"{_display.num(lo)} .. {_display.num(hi)}",
                _display.num(rate) if math.isfinite(rate) else "none", a.delay,
                _OTHER[name] if a.coupling is not None else "",
                a.sign * a.state[2] + 0.0, a.sign * a.out[2] + 0.0, float(a.state[K.STATE_SIZE]),
            ))  # fmt: skip
        header = ("axis", "model", "sign", "input limits (counts)", "max rate (counts/s)",
                  "delay (s)", "reads", "command (counts)", "angle (deg)", "time (s)")  # fmt: skip
        title = f"<b>Compensator</b> {_display.esc(', '.join(self._axes))}"
        return _display.table(header, rows, title)


def _number(func: str, name: str, x) -> float:
    """``x`` as a float (NaN and inf kept: the caller says what it needs), CalibError
    for a str, an array (a 1-element one included), None or a bool."""
    if type(x) is float:  # the control loop's common case, one check
        return x
    return as_real(func, name, x, finite=False, none_ok=False) if x is not None else math.nan


def _check_axis_values(name, c, r, p, cfg, v0, coupling, other_start, params) -> None:
    """CalibError when an axis's numbers cannot be a fitted model's (a JSON edited or
    damaged): kernel arrays and parameters finite, limits ordered, rate > 0, quantum
    >= 0, tolerance > 0, the start input ``v0`` (model convention) inside the limits
    (:meth:`OnlineInverse.from_dict` checks what the constructor's model checks)."""
    arrays = {"c": c, "r": r, "p": p}
    if coupling is not None:
        arrays.update({"coupling.c": coupling[0], "coupling.r": coupling[1],
                       "coupling.p": coupling[2]})  # fmt: skip
    for key, a in arrays.items():
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise CalibError(
                f"{name}: {key}[{bad[0]}] is {a[bad[0]]}; the kernel coefficients must be "
                "finite (re-create the compensator from its fit)"
            )
    for key, x in params.items():
        if not isinstance(x, (int, float)) or isinstance(x, bool) or not math.isfinite(x):
            raise CalibError(f"{name}: params['{key}'] is {x!r}; give a finite number")
    kappa, vf, db, lo, hi, rate, quantum, tol = (float(x) for x in cfg)
    checked_limits((lo, hi), rate, quantum, f"{name}: ")
    for key, ok in (("kappa", math.isfinite(kappa)), ("v_f", vf > 0),
                    ("deadband_counts", math.isfinite(db) and db >= 0),
                    ("tol_deg", math.isfinite(tol) and tol >= 0),
                    ("other_start_counts", math.isfinite(other_start))):  # fmt: skip
        if not ok:
            value = {"kappa": kappa, "v_f": vf, "deadband_counts": db, "tol_deg": tol,
                     "other_start_counts": other_start}[key]  # fmt: skip
            raise CalibError(f"{name}: {key} = {value:g} is not valid (see docs/compensate.md)")
    if not lo <= v0 <= hi:
        raise CalibError(
            f"{name}: start input {v0:g} (the model's convention) is outside the input range "
            f"{lo:g}..{hi:g}"
        )


def _checked_history(history, models) -> dict[str, np.ndarray]:
    """Axis -> counts of a ``history`` (dict), every compensated axis and the other
    motor of a coupled one, non-empty, finite, of one length (one-line CalibError)."""
    if not isinstance(history, dict):
        raise CalibError("Compensator: history must be a dict axis -> signed counts")
    need = set(models) | {_OTHER[n] for n, m in models.items() if is_coupled(_base_and_delay(m)[0])}
    missing = sorted(need - set(history))
    if missing:
        raise CalibError(f"Compensator: history needs the counts of {', '.join(missing)} too")
    out = {}
    for name in sorted(need):
        out[name] = as_1d_float("Compensator", f"history['{name}']", history[name], min_size=1,
                                hint="give the signed counts sent, all finite")  # fmt: skip
    if len({h.size for h in out.values()}) != 1:
        raise CalibError("Compensator: every motor's history needs the same number of counts")
    return out


def _floats(a) -> list[float]:
    return [float(x) for x in a]


def _axis_dict(name: str, ax) -> dict:
    """:meth:`OnlineInverse.to_dict`'s record of axis ``name`` (its ``_Axis`` ``ax``)."""
    kappa, vf, db, lo, hi, rate, quantum, tol = (float(x) for x in ax.cfg)
    st = ax.get()
    state = {
        "operators": [list(row) for row in st.operators],
        "direction": st.direction,
        "anchor": st.anchor,
        "last_input": st.last_input,
        "last_output_deg": st.last_output_deg,
        "init": st.init,
        "last_move_s": st.last_move_s,
        "time_s": st.time_s,
    }
    coupling = None
    if ax.coupling is not None:
        cc, cr, cp = ax.coupling
        coupling = {"other_axis": _OTHER[name], "c": _floats(cc), "r": _floats(cr),
                    "p": _floats(cp), "other_start_counts": ax.other_start}  # fmt: skip
        state["coupling"] = {
            "operators": list(st.coupling_operators),
            "other_counts": st.other_counts,
            "coupling_deg": st.coupling_deg,
        }
    return {
        "model": ax.kind,
        "kernel_kind": KIND_NAMES[ax.code],
        "params": ax.params,
        "c": _floats(ax.c),
        "r": _floats(ax.r),
        "p": _floats(ax.p),
        "kappa": kappa,
        "v_f": vf if math.isfinite(vf) else None,
        "deadband_counts": db,
        "v_limits": [lo, hi],
        "max_counts_per_s": rate if math.isfinite(rate) else None,
        "quantum": quantum,
        "tol_deg": tol,
        "sign": ax.sign,
        "start_counts": ax.start,
        "delay_s": ax.delay,
        "coupling": coupling,
        "state": state,
    }
