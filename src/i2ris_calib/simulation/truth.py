"""True bending angles: EGPI hysteresis per dataset, hidden effects, continuity.

For each dataset the I2RIS EGPI model (Eq16-23, :mod:`i2ris_calib.hysteresis.models`)
with the hysteresis engineer's paper-like parameters
(:func:`i2ris_calib.hysteresis.presets.paper_like_params`, scaled to the dataset's
amplitude; overridable per dataset with ``models``) maps |encoder| -> |angle|; the angle is ``sign * model(|v|)`` (the paper fits
negative-input datasets on absolute values). Hidden effects (config ``effects``)
wrap the model via :func:`i2ris_calib.diagnosis.effects.build_model`.

Continuity: each dataset starts from the model's initial state at zero input. The
model output at zero input (small, from the envelope offsets) is faded in with a
raised cosine over the second half of the initial ``rest_s``, and the residual
angle left at zero input after the last return (backlash) is faded out over the
final ``settle_s`` (input held at 0 in both phases). So each dataset starts and
ends at rest at exactly 0 deg and the angle is continuous across datasets. The
other axis holds 0 deg during a dataset. (Inside a dataset the EGPI output itself
may step where it switches branch at the flag point, Eq21; that is the model.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.simulation.config import SimulationConfig
from i2ris_calib.simulation.trajectory import Block, session_blocks, session_inputs

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
    """

    t_s: np.ndarray
    enc_yaw: np.ndarray
    enc_pitch: np.ndarray
    yaw_deg: np.ndarray
    pitch_deg: np.ndarray
    block: np.ndarray
    params: dict


def dataset_model(cfg: SimulationConfig, block: Block):
    """The truth model of one dataset (EGPI wrapped by the hidden effects)."""
    from i2ris_calib.hysteresis.models import i2ris_egpi_model
    from i2ris_calib.hysteresis.presets import paper_like_params

    amp = cfg.amplitude_counts[0 if block.axis == "yaw" else 1]
    values = dict(paper_like_params(block.name, v_max_counts=amp))
    values.update(cfg.models.get(block.name, {}))
    model = i2ris_egpi_model(**values)
    return apply_hidden_effects(model, cfg.effects)


def apply_hidden_effects(model, effects: dict):
    """Wrap ``model`` with the configured hidden effects (diagnosis effect catalogue)."""
    if not effects:
        return model
    from i2ris_calib.diagnosis.effects import build_model

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
    from i2ris_calib.diagnosis.effects import model_values
    from i2ris_calib.hysteresis.model import Signals

    blocks = session_blocks(cfg)
    if t_s is None:
        t_s = np.arange(-2.0, blocks[-1].t1_s + 2.0, 1.0 / TRUTH_RATE_HZ)
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
