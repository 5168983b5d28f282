"""True bending angles: EGPI hysteresis, hidden effects; two truth modes.

``truth = "whole_history"`` (:func:`whole_history_angle`): exactly what the data
layer (:mod:`i2ris_calib.data.dataset`) assumes. Per axis, one EGPI per motion
direction runs over the WHOLE history on the input that direction sees (``"+"``:
``max(enc, 0)``, ``"-"``: ``max(-enc, 0)``); the angle of a sample is
``+EGPI_plus`` on the samples attributed to ``"+"`` and ``-EGPI_minus`` on those
attributed to ``"-"`` (:func:`i2ris_calib.data.dataset.direction_of_samples` with the
zero band :func:`~i2ris_calib.data.dataset.input_bands` derives from the axis's
input; the EGPI's ``v'`` dead band is the derived one too). Nothing is faded or
reset: the angle at rest is the model's residual, and it jumps where the
attribution changes direction (``+`` residual -> ``-`` model), as the data layer's
two-model assumption implies. With ``zero_start`` the envelope offsets ``a4``, ``a6``
of each model are shifted by the same amount so that the model's output from its
initial state at zero input is exactly 0 deg (the tracking zero is the pose at the
start). Frames take the truth evaluated exactly at their times
(:func:`truth_at`, no interpolation across the model's steps).

``truth = "blocks"`` (the Fig-5 sample):

For each dataset the I2RIS EGPI model (Eq16-23, :mod:`i2ris_calib.hysteresis.models`)
with the hysteresis engineer's paper-like parameters
(:func:`i2ris_calib.hysteresis.presets.paper_like_params`, scaled to the dataset's
amplitude; overridable per dataset with ``models``) maps |encoder| -> |angle|; the angle is ``sign * model(|v|)`` (the paper fits
negative-input datasets on absolute values). Hidden effects (config ``effects``)
wrap the model via :func:`i2ris_calib.hysteresis.effects.build_model`.

Continuity: each dataset starts from the model's initial state at zero input. The
model output at zero input (small, from the envelope offsets) is faded in with a
raised cosine over the second half of the initial ``rest_s``, and the residual
angle left at zero input after the last return (backlash) is faded out over the
final ``settle_s`` (input held at 0 in both phases). So each dataset starts and
ends at rest at exactly 0 deg and the angle is continuous across datasets. The
other axis holds 0 deg during a dataset. (Inside a dataset the EGPI output itself
may step where it switches branch at the flag point, Eq20; that is the model.)
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from i2ris_calib.data.dataset import direction_input, direction_of_samples, input_bands
from i2ris_calib.hysteresis.effects import build_model, model_values
from i2ris_calib.hysteresis.kinds import LAB_TRUTH
from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import paper_like_params
from i2ris_calib.model import Signals
from i2ris_calib.simulation.config import SimulationConfig
from i2ris_calib.simulation.lab import lab_drive
from i2ris_calib.simulation.trajectory import (
    Block,
    motion_duration_s,
    session_blocks,
    session_inputs,
)
from i2ris_calib.simulation.two_motor import two_motor_angles

#: Controller-clock sampling of the truth (Hz); frames interpolate from it.
TRUTH_RATE_HZ = 1000.0


@dataclass(frozen=True)
class Truth:
    """Truth on the fine controller grid (all arrays shape (n,)).

    Attributes
    ----------
    t_s : motion time (s from the motion start, controller clock)
    enc_yaw, enc_pitch : encoder counts (int)
    yaw_deg, pitch_deg : true bending angles (deg)
    block : dataset index per sample (-1 outside every dataset)
    params : parameter values per dataset name (incl. effect parameters)
    mode : the truth mode (``"blocks"``, ``"whole_history"`` or ``"lab"``: the two-motor
        truth of :mod:`i2ris_calib.simulation.lab`, the grid starting with its burn-in)
    bands : whole_history: per axis ``{"zero_band", "deadband"}`` (counts) used
    """

    t_s: np.ndarray
    enc_yaw: np.ndarray
    enc_pitch: np.ndarray
    yaw_deg: np.ndarray
    pitch_deg: np.ndarray
    block: np.ndarray
    params: dict
    mode: str = "blocks"
    bands: dict = field(default_factory=dict)


def dataset_model(cfg: SimulationConfig, block: Block):
    """The truth model of one dataset (EGPI wrapped by the hidden effects)."""
    amp = cfg.amplitude_counts[0 if block.axis == "yaw" else 1]
    values = dict(paper_like_params(block.name, v_max_counts=amp))
    values.update(cfg.models.get(block.name, {}))
    model = i2ris_egpi_model(**values)
    return apply_hidden_effects(model, cfg.effects)


def apply_hidden_effects(model, effects: dict):
    """Wrap ``model`` with the configured hidden effects (diagnosis effect catalogue)."""
    if not effects:
        return model

    return build_model(model, effects)


def session_truth(cfg: SimulationConfig, t_s: np.ndarray | None = None) -> Truth:
    """Evaluate inputs and true angles of the whole session on a fine grid.

    Parameters
    ----------
    cfg : SimulationConfig
    t_s : ndarray, optional
        Motion times (controller s); default a ``TRUTH_RATE_HZ`` grid over the motion
        plus one second either side.
    """
    if cfg.protocol == "lab":
        return _lab_truth(cfg, t_s)
    blocks = session_blocks(cfg)
    if t_s is None:
        t_s = np.arange(-2.0, motion_duration_s(cfg) + 2.0, 1.0 / TRUTH_RATE_HZ)
    if cfg.truth == "whole_history":
        return _whole_history_truth(cfg, np.asarray(t_s, dtype=float), blocks)
    ey, ep = session_inputs(cfg, t_s)
    ang = {"yaw": np.zeros(t_s.shape), "pitch": np.zeros(t_s.shape)}
    enc = {"yaw": ey, "pitch": ep}
    blk = np.full(t_s.shape, -1)
    params = {}
    for i, b in enumerate(blocks):
        inside = (t_s >= b.t0_s) & (t_s <= b.t1_s)
        if not inside.any():
            continue
        other = "pitch" if b.axis == "yaw" else "yaw"
        model = dataset_model(cfg, b)
        vals = model_values(model)
        sig = Signals(
            v=np.abs(enc[b.axis][inside]).astype(float),
            t_s=t_s[inside],
            v_other=np.abs(enc[other][inside]).astype(float),
            theta_other_deg=np.abs(ang[other][inside]),
        )
        theta = b.sign * np.asarray(model.evaluate(sig, vals), dtype=float)
        ang[b.axis][inside] = theta * continuity_weight(t_s[inside], b, cfg.rest_s)
        blk[inside] = i
        params[b.name] = dict(
            zip([p.name for p in model.parameters], map(float, vals), strict=True)
        )
    return Truth(t_s, ey, ep, ang["yaw"], ang["pitch"], blk, params)


def continuity_weight(t_s: np.ndarray, block: Block, rest_s: float) -> np.ndarray:
    """Fade-in over the second half of the rest, fade-out over the settle phase, (n,)."""
    half = max(rest_s / 2.0, 1e-9)
    x_in = np.clip((t_s - block.t0_s - half) / half, 0.0, 1.0)
    span = max(block.t1_s - block.settle_start_s, 1e-9)
    x_out = np.clip((t_s - block.settle_start_s) / span, 0.0, 1.0)
    return 0.25 * (1.0 - np.cos(np.pi * x_in)) * (1.0 + np.cos(np.pi * x_out))


# --------------------------------------------------------------------------- whole history


def zero_start_shift(model, values: np.ndarray) -> float:
    """Shift c (deg) of ``a4`` and ``a6`` that makes the model's output 0 deg from its
    initial state at zero input (bisection; the output is non-decreasing in c).

    Parameters
    ----------
    model : I2RISEGPIModel or ContinuousEGPIModel (possibly wrapped by effects)
    values : ndarray, shape (p,)
        Its parameter values (a4 and a6 are read by name).
    """
    names = [p.name for p in model.parameters]
    i4, i6 = names.index("a4"), names.index("a6")

    def y0(c: float) -> float:
        x = np.array(values, dtype=float)
        x[i4] += c
        x[i6] += c
        return float(model.evaluate(_signals(np.zeros(2)), x)[0])

    lo, hi = -200.0, 200.0
    if y0(lo) > 0 or y0(hi) < 0:
        raise ValueError("zero_start: no shift of a4, a6 makes the initial output 0")
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if y0(mid) < 0 else (lo, mid)
    return 0.5 * (lo + hi)


def _signals(v, t_s=None, v_other=None, theta_other=None):
    return Signals(v=np.asarray(v, dtype=float), t_s=t_s, v_other=v_other,
                   theta_other_deg=theta_other)  # fmt: skip


def direction_model(cfg: SimulationConfig, name: str, deadband: float):
    """Truth model of one axis and direction (``"yaw+"``, ...) for ``whole_history``:
    EGPI with ``paper_like_params(name)`` scaled to the axis's amplitude, the
    ``models`` overrides, the given ``v'`` dead band (counts), the zero-start shift
    (``zero_start``), wrapped by the hidden effects. Returns ``(model, values)``."""
    amp = cfg.amplitude_counts[0 if name.startswith("yaw") else 1]
    values = dict(paper_like_params(name, v_max_counts=amp))
    values.update(cfg.models.get(name, {}))
    base = i2ris_egpi_model(deadband_counts=float(deadband), **values)
    if cfg.zero_start:
        c = zero_start_shift(base, base.values)
        base = base.with_values({"a4": values["a4"] + c, "a6": values["a6"] + c})
    model = apply_hidden_effects(base, cfg.effects)
    return model, np.asarray(model_values(model), dtype=float)


def whole_history_angle(
    enc: np.ndarray,
    models: dict,
    zero_band: float,
    t_s: np.ndarray | None = None,
    enc_other: np.ndarray | None = None,
    theta_other_deg: np.ndarray | None = None,
) -> np.ndarray:
    """The data layer's truth for one axis: angle (deg), shape (n,).

    Parameters
    ----------
    enc : ndarray, shape (n,)
        The axis's signed input in time order (counts), the whole history.
    models : dict
        ``{"+": (model, values), "-": (model, values)}``: each direction's model
        (output in that direction's convention, |deg| for ``"-"``) and its values.
    zero_band : float
        Attribution zero band (counts), as the data layer derives it.
    t_s, enc_other, theta_other_deg : ndarray, shape (n,), optional
        Sample times (s) and the other axis's signed input and angle (effects).

    Returns
    -------
    ndarray, shape (n,)
        ``+model_plus(max(enc, 0))`` on samples attributed to ``"+"``,
        ``-model_minus(max(-enc, 0))`` on those attributed to ``"-"``, both models run
        over every sample. An input that never leaves the zero band is a ``"+"``
        sample.
    """
    enc = np.asarray(enc, dtype=float)
    d = direction_of_samples(enc, zero_band)
    out = np.zeros(enc.size)
    for direction, sign in (("+", 1), ("-", -1)):
        mine = (d == sign) | ((d == 0) & (sign > 0))
        if not mine.any():
            continue
        model, values = models[direction]
        sig = _signals(direction_input(enc, direction), t_s, enc_other, theta_other_deg)
        out[mine] = sign * np.asarray(model.evaluate(sig, values), dtype=float)[mine]
    return out


def _axis_models(cfg: SimulationConfig, axis: str, bands: dict) -> dict:
    return {d: direction_model(cfg, f"{axis}{d}", bands[axis]["deadband"]) for d in ("+", "-")}


def _whole_history_angles(
    cfg: SimulationConfig, t_s: np.ndarray, enc: dict, bands: dict
) -> tuple[dict, dict]:
    """Angles {axis: (n,)} and parameters {name: dict} on samples ``t_s`` (s) with
    inputs ``enc`` {axis: (n,)}; effects see the other axis's effect-free angle."""
    models = {a: _axis_models(cfg, a, bands) for a in ("yaw", "pitch")}
    plain = {}
    if cfg.effects:  # effect-free angles first: what a coupling effect reads
        bare = replace(cfg, effects={})
        for a in ("yaw", "pitch"):
            plain[a] = whole_history_angle(
                enc[a], _axis_models(bare, a, bands), bands[a]["zero_band"], t_s
            )
    ang = {}
    for a in ("yaw", "pitch"):
        o = "pitch" if a == "yaw" else "yaw"
        ang[a] = whole_history_angle(
            enc[a], models[a], bands[a]["zero_band"], t_s,
            enc_other=np.asarray(enc[o], dtype=float), theta_other_deg=plain.get(o),
        )  # fmt: skip
    params = {
        f"{a}{d}": dict(
            zip([p.name for p in m.parameters], map(float, model_values(m)), strict=True)
        )
        for a in ("yaw", "pitch")
        for d, (m, _) in models[a].items()
    }
    return ang, params


def _whole_history_truth(cfg: SimulationConfig, t_s: np.ndarray, blocks: list[Block]) -> Truth:
    ey, ep = session_inputs(cfg, t_s)
    enc = {"yaw": ey, "pitch": ep}
    bands = {}
    for a in ("yaw", "pitch"):
        b = input_bands(enc[a])
        bands[a] = {"zero_band": b.zero_band, "deadband": b.deadband}
    ang, params = _whole_history_angles(cfg, t_s, enc, bands)
    blk = np.full(t_s.shape, -1)
    for i, b in enumerate(blocks):
        blk[(t_s >= b.t0_s) & (t_s <= b.t1_s)] = i
    return Truth(t_s, ey, ep, ang["yaw"], ang["pitch"], blk, params, "whole_history", bands)


def _lab_truth(cfg: SimulationConfig, t_s: np.ndarray | None) -> Truth:
    """The lab protocol's truth: its whole driving grid (burn-in included), or ``t_s``."""
    d = lab_drive(cfg)
    params = {"yaw": d.params["yaw"], "pitch": d.params["pitch"], "c": d.params["c"],
              "coupling": d.params["coupling"], "model": LAB_TRUTH,
              "straight_motion_s": list(d.straight_s)}  # fmt: skip
    full = Truth(d.t_s, d.enc_yaw.astype(np.int64), d.enc_pitch.astype(np.int64), d.yaw_deg,
                 d.pitch_deg, np.full(d.t_s.shape, -1), params, "lab")  # fmt: skip
    if t_s is None:
        return full
    tq = np.asarray(t_s, dtype=float)
    ey = np.rint(np.interp(tq, d.t_s, d.enc_yaw)).astype(np.int64)
    ep = np.rint(np.interp(tq, d.t_s, d.enc_pitch)).astype(np.int64)
    yaw, pitch = truth_at(cfg, full, tq)
    return Truth(tq, ey, ep, yaw, pitch, np.full(tq.shape, -1), params, "lab")


def truth_at(cfg: SimulationConfig, truth: Truth, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """True (yaw, pitch) angles (deg) at motion times ``t_s`` (any shape), each like ``t_s``.

    ``blocks``: linear interpolation of the fine grid. ``whole_history`` and ``lab``:
    exact - the models run over the fine grid merged with ``t_s`` (inputs linearly interpolated
    there, as a synced table interpolates the encoder log), so a sample next to one of
    the model's steps (flag point, direction change) is on one side of it, never a
    blend of both.
    """
    tq = np.asarray(t_s, dtype=float)
    if truth.mode not in ("whole_history", "lab"):
        return np.interp(tq, truth.t_s, truth.yaw_deg), np.interp(tq, truth.t_s, truth.pitch_deg)
    flat = tq.ravel()
    allt = np.concatenate([truth.t_s, flat])
    order = np.argsort(allt, kind="stable")
    tm = allt[order]
    enc = {
        "yaw": np.interp(tm, truth.t_s, truth.enc_yaw.astype(float)),
        "pitch": np.interp(tm, truth.t_s, truth.enc_pitch.astype(float)),
    }
    if truth.mode == "lab":
        ang = dict(zip(("yaw", "pitch"), two_motor_angles(truth.params, enc["yaw"], enc["pitch"]),
                       strict=True))  # fmt: skip
    else:
        ang, _ = _whole_history_angles(cfg, tm, enc, truth.bands)
    pos = np.empty(order.size, dtype=int)
    pos[order] = np.arange(order.size)
    q = pos[truth.t_s.size :]
    return ang["yaw"][q].reshape(tq.shape), ang["pitch"][q].reshape(tq.shape)
