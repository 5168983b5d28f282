"""Online compensation: a :class:`Compensator` a control loop calls once per cycle.

The batch path (:func:`~i2ris_calib.compensation.inverse.compensate`) inverts a whole
target; a controller knows one target sample at a time. :class:`Compensator` carries
the inverse's state from one call to the next and takes exactly the batch's step
(:func:`~i2ris_calib.compensation.kernel.step_one` runs the compiled
:func:`~i2ris_calib.compensation.kernel._step` the batch loop runs), so the same target
sampled the same way gives the same commands as ``compensate(..., v_initial=start,
entry=False, repair_spikes=False)`` (docs/compensate.md, "Online use").

Everything a controller needs is in :meth:`Compensator.to_dict` (plain numbers: model
kind and kernel parameters, limits, rate, state; schema :data:`SCHEMA`), which
:meth:`Compensator.from_dict` restores without the model objects. Files are read and
written by :mod:`i2ris_calib.io.online`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from i2ris_calib.compensation import kernel as K
from i2ris_calib.compensation.inverse import (
    STATUS_NAMES,
    _base_and_delay,
    default_tol,
    is_coupled,
    kernel_params,
)
from i2ris_calib.errors import CalibError

#: Schema of :meth:`Compensator.to_dict` (the JSON a controller loads)
SCHEMA = "i2ris-calib.compensator/1"
#: Kernel kind code <-> name in the JSON
KIND_NAMES = {K.KIND_GPI: "gpi", K.KIND_EGPI: "egpi", K.KIND_EGPI_C: "egpi_c", K.KIND_AGPI: "agpi"}
_KIND_CODES = {v: k for k, v in KIND_NAMES.items()}
AXES = ("yaw", "pitch")
#: Status code -> the flag of a step (as the batch's ``flags`` names them); reached: none
STEP_FLAGS = {
    K.STATUS_OK: (),
    K.STATUS_ABOVE: ("above_range",),
    K.STATUS_BELOW: ("below_range",),
    K.STATUS_RATE: ("rate_limited",),
    K.STATUS_GAP: ("output_step",),
    K.STATUS_DELAY: ("within_delay",),
}
_STATE_NAMES = ("direction", "anchor", "last_input", "last_output_deg", "init", "last_move_s")


class AxisCommand(NamedTuple):
    """One axis's result of :meth:`Compensator.step`.

    Attributes
    ----------
    counts : float
        Signed encoder counts to send (whole counts; the robot's sign).
    predicted_deg : float
        The model's angle after this command (deg, robot's sign).
    status : int
        0 = target reached, else a :data:`~i2ris_calib.compensation.inverse.STATUS_NAMES` code.
    flags : tuple of str
        ``()`` when reached, else one of ``above_range``, ``below_range``,
        ``rate_limited``, ``output_step``.
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
        The model's output after it (deg, model convention).
    init : bool
        True: no command yet and no start state (the first command sets the state).
    last_move_s : float
        Time of the last command change (s; for a rate limit below one count per step).
    time_s : float
        Time of the last command (s; 0 at the start state).
    """

    operators: tuple[tuple[float, ...], ...]
    direction: int
    anchor: float
    last_input: float
    last_output_deg: float
    init: bool
    last_move_s: float
    time_s: float


class _Axis:
    """One axis's compiled inverse: kernel arrays, limits, state (mutable, private)."""

    __slots__ = ("name", "code", "c", "r", "p", "cfg", "w", "state", "out", "sign", "start",
                 "params", "kind", "prm", "mem")  # fmt: skip

    def __init__(self, name, kind, code, c, r, p, cfg, sign, start, params):
        self.name = name
        self.kind = kind
        self.code = int(code)
        self.c, self.r, self.p, self.cfg = (
            np.ascontiguousarray(a, dtype=float) for a in (c, r, p, cfg)
        )
        self.sign = float(sign)
        self.start = float(start)
        self.params = dict(params)
        if self.p.size != self.r.size or self.c.size != (9 if self.code == K.KIND_AGPI else 6):
            raise CalibError(f"{name}: kernel arrays c, r, p do not fit the kind {kind}")
        self.prm, self.mem = K.pack(self.c, self.r, self.p, self.cfg)
        m2 = 2 * self.p.size
        self.w = self.mem[:m2].reshape(2, self.p.size)  # views into mem
        self.state = self.mem[m2 : m2 + K.STATE_SIZE + 1]
        self.out = self.mem[m2 + K.STATE_SIZE + 1 :]
        self.reset()

    def reset(self):
        self.w[:] = 0.0
        kappa, vf, db = self.cfg[:3]
        K.start_state(self.code, self.c, self.r, self.p, kappa, vf, db, self.start * self.sign,
                      self.w, self.state)  # fmt: skip

    def get(self) -> AxisState:
        s = self.state
        return AxisState(
            operators=tuple(tuple(float(x) for x in row) for row in self.w),
            direction=int(s[0]), anchor=float(s[1]), last_input=float(s[2]),
            last_output_deg=float(s[3]), init=bool(s[4]), last_move_s=float(s[5]),
            time_s=float(s[K.STATE_SIZE]),
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
        self.w[:] = w
        self.state[:] = [float(x) for x in vals]


def _axis_from_model(name, model, v_limits, sign, max_rate, start, quantum, tol_deg):
    base, delay = _base_and_delay(model)
    if delay > 0:
        raise CalibError(
            f"Compensator: the {name} model has a time delay ({delay:g} s); online inversion "
            "needs the target that far ahead: use compensate() on the whole target"
        )
    if is_coupled(base):
        raise CalibError(
            f"Compensator: the {name} model ({base.name}) reads the other motor's commands; "
            "the online compensator inverts gpi, egpi, egpi_c and agpi (use compensate())"
        )
    code, c, r, p, kappa, vf, db = kernel_params(base)
    lo, hi = (float(x) for x in v_limits)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise CalibError(f"Compensator: {name} v_limits must be finite with lo < hi")
    rate = math.inf if max_rate is None else float(max_rate)
    if not rate > 0:
        raise CalibError(f"Compensator: {name} max_counts_per_s must be > 0, got {rate:g}")
    if not (quantum >= 0 and math.isfinite(quantum)):
        raise CalibError(f"Compensator: quantum must be >= 0, got {quantum:g}")
    v0 = float(sign) * float(start)
    if quantum > 0:
        v0 = float(np.round(v0 / quantum) * quantum)
    if not lo <= v0 <= hi:
        raise CalibError(
            f"Compensator: {name} start counts {start:g} are outside the input range "
            f"{min(sign * lo, sign * hi):g}..{max(sign * lo, sign * hi):g}"
        )
    tol = default_tol(code, c, p, float(quantum)) if tol_deg is None else float(tol_deg)
    cfg = np.array([kappa, vf, db, lo, hi, rate, quantum, tol], dtype=float)
    params = {k: float(x) for k, x in base.value_dict().items()}
    return _Axis(name, base.name, code, c, r, p, cfg, sign, sign * v0, params)


class Compensator:
    """Online feedforward compensation: one target sample in, one command per axis out.

    Parameters
    ----------
    models : dict
        Axis (``"yaw"``, ``"pitch"``) -> fitted model (gpi, egpi, egpi_c or agpi; the
        model's convention: input >= 0 of a motion direction, or the signed input for
        agpi).
    v_limits : dict
        Axis -> (lo, hi): allowed input (model convention, counts), e.g. the fitted range.
    signs : dict, optional
        Axis -> +1 or -1: robot's signed counts and angle = sign x the model's (-1 for a
        ``-`` dataset). Default +1.
    max_counts_per_s : dict or float, optional
        Rate limit (counts/s) per axis or for all; None or ``inf``: none.
    start_counts : dict or float
        Signed counts the motor rests at before the first step (robot's sign).
    quantum : float
        Command resolution (1 = whole counts).
    tol_deg : float, optional
        As :func:`~i2ris_calib.compensation.inverse.compensate` (default from the model).

    Notes
    -----
    ``step`` gives the commands ``compensate(model, target, t, v_limits=...,
    max_rate=..., v_initial=start, entry=False, repair_spikes=False)`` gives for the
    same samples (to 1e-9): the rate limit moves the command from the start state (no
    separate entry ramp), and there is no spike repair (it needs the next sample).
    """

    def __init__(self, models, v_limits, signs=None, max_counts_per_s=None, start_counts=0.0,
                 quantum=1.0, tol_deg=None):  # fmt: skip
        if not isinstance(models, dict) or not models or any(a not in AXES for a in models):
            raise CalibError("Compensator: models must be a dict axis ('yaw', 'pitch') -> model")
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
                tol_deg,
            )  # fmt: skip

    @classmethod
    def _from_axes(cls, axes: dict[str, _Axis]) -> Compensator:
        obj = cls.__new__(cls)
        obj._axes = axes
        return obj

    @property
    def axes(self) -> tuple[str, ...]:
        """The compensated axes."""
        return tuple(self._axes)

    def step(
        self,
        target_yaw_deg: float | None = None,
        target_pitch_deg: float | None = None,
        dt_s: float = 0.01,
    ) -> dict[str, AxisCommand]:
        """Commands for one target sample, ``dt_s`` seconds after the previous step
        (or the start state).

        Parameters
        ----------
        target_yaw_deg, target_pitch_deg : float
            Desired angle (deg, robot's sign) of every compensated axis.
        dt_s : float
            Time since the previous step (s), > 0.

        Returns
        -------
        dict
            Axis -> :class:`AxisCommand` (signed counts, predicted angle, status, flags).
        """
        if not dt_s > 0 or dt_s == math.inf:
            raise CalibError(f"Compensator.step: dt_s must be a time > 0 s, got {dt_s!r}")
        out = {}
        for name, ax in self._axes.items():
            tk = target_yaw_deg if name == "yaw" else target_pitch_deg
            if tk is None or not math.isfinite(tk):
                raise CalibError(f"Compensator.step: give a finite target_{name}_deg, got {tk!r}")
            K.step_one(ax.code, ax.prm, ax.mem, ax.sign * tk, dt_s)
            o = ax.out
            st = int(o[3])
            out[name] = AxisCommand(ax.sign * o[0] + 0.0, ax.sign * o[2], st, STEP_FLAGS[st])
        return out

    @property
    def state(self) -> dict[str, AxisState]:
        """Axis -> :class:`AxisState` (a copy: a later step does not change it)."""
        return {name: ax.get() for name, ax in self._axes.items()}

    def reset(self, state: dict[str, AxisState] | None = None) -> None:
        """Back to the start state (at the start counts), or to ``state`` (as
        :attr:`state` returned it, e.g. saved before a pause)."""
        if state is None:
            for ax in self._axes.values():
                ax.reset()
            return
        if not isinstance(state, dict) or set(state) != set(self._axes):
            raise CalibError(f"Compensator.reset: give a state of the axes {', '.join(self._axes)}")
        for name, st in state.items():
            self._axes[name].set(st)

    def to_dict(self) -> dict:
        """Everything a controller needs, in plain numbers (docs/compensate.md, "Online
        use"): per axis the model kind and its parameters, the kernel arrays (``c``,
        ``r``, ``p``), limits, rate, resolution, tolerance, sign, start counts and the
        current state."""
        axes = {}
        for name, ax in self._axes.items():
            kappa, vf, db, lo, hi, rate, quantum, tol = (float(x) for x in ax.cfg)
            st = ax.get()
            axes[name] = {
                "model": ax.kind,
                "kernel_kind": KIND_NAMES[ax.code],
                "params": ax.params,
                "c": [float(x) for x in ax.c],
                "r": [float(x) for x in ax.r],
                "p": [float(x) for x in ax.p],
                "kappa": kappa,
                "v_f": vf if math.isfinite(vf) else None,
                "deadband_counts": db,
                "v_limits": [lo, hi],
                "max_counts_per_s": rate if math.isfinite(rate) else None,
                "quantum": quantum,
                "tol_deg": tol,
                "sign": ax.sign,
                "start_counts": ax.start,
                "state": {
                    "operators": [list(row) for row in st.operators],
                    "direction": st.direction,
                    "anchor": st.anchor,
                    "last_input": st.last_input,
                    "last_output_deg": st.last_output_deg,
                    "init": st.init,
                    "last_move_s": st.last_move_s,
                    "time_s": st.time_s,
                },
            }
        return {"schema": SCHEMA, "statuses": {str(k): v for k, v in STATUS_NAMES.items()},
                "axes": axes}  # fmt: skip

    @classmethod
    def from_dict(cls, doc: dict) -> Compensator:
        """The compensator :meth:`to_dict` described (no model objects needed);
        CalibError naming the key for a document that is not one."""
        if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
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
                ax = _Axis(name, str(a["model"]), code, a["c"], a["r"], a["p"], cfg,
                           float(a["sign"]), float(a["start_counts"]), a["params"])  # fmt: skip
                s = a["state"]
                ax.set(AxisState(
                    operators=tuple(tuple(row) for row in s["operators"]),
                    direction=int(s["direction"]), anchor=float(s["anchor"]),
                    last_input=float(s["last_input"]),
                    last_output_deg=float(s["last_output_deg"]), init=bool(s["init"]),
                    last_move_s=float(s["last_move_s"]), time_s=float(s["time_s"]),
                ))  # fmt: skip
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
