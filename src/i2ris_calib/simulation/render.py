"""Render microscope frames of the marker cube: exact coverage, blur, light, noise.

Pipeline per frame: exact-area rasterisation of the visible cube faces and marker
ink (:mod:`.raster`) in a region of interest, averaged over ``motion_blur_samples``
sub-frame poses; composited over a smooth background; the same uneven illumination
multiplies everything; Gaussian defocus (grows with the depth offset); the sync
flash brightens the whole frame; additive Gaussian sensor noise; rounding to uint8.
"""

from __future__ import annotations

import cv2
import numpy as np

from i2ris_calib.simulation.config import SimulationConfig
from i2ris_calib.simulation.raster import accumulate_quads
from i2ris_calib.simulation.scene import CameraModel, CubeModel, projected_quads


def illumination_field(cfg: SimulationConfig) -> np.ndarray:
    """Relative illumination (h, w) float32: radial fall-off and a left-right ramp."""
    h, w = cfg.height_px, cfg.width_px
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    xn = (x - (w - 1) / 2) / ((w - 1) / 2)
    yn = (y - (h - 1) / 2) / ((h - 1) / 2)
    r2 = (xn**2 + yn**2) / 2.0
    return (
        (1.0 - cfg.illumination_falloff * r2) * (1.0 + cfg.illumination_gradient * xn / 2)
    ).astype(np.float32)


def background(cfg: SimulationConfig, rng: np.random.Generator) -> np.ndarray:
    """Smooth textured background (h, w) float32, grey levels before illumination."""
    h, w = cfg.height_px, cfg.width_px
    small = rng.normal(0.0, 1.0, (max(h // 32, 2), max(w // 32, 2))).astype(np.float32)
    tex = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    tex = cv2.GaussianBlur(tex, (0, 0), 12)
    tex /= max(float(tex.std()), 1e-6)
    return (cfg.background_gray + 8.0 * tex).astype(np.float32)


class FrameRenderer:
    """Renders one camera's frames; holds the static background and illumination."""

    def __init__(self, cfg: SimulationConfig, cam: CameraModel, cube: CubeModel, seed: int):
        self.cfg, self.cam, self.cube = cfg, cam, cube
        self.rng = np.random.default_rng(seed)
        self.illum = illumination_field(cfg)
        self.base = background(cfg, self.rng) * self.illum

    def scene(self, rotations: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, tuple, float]:
        """Coverage-weighted grey ``S`` and coverage ``C`` in a ROI, averaged over poses.

        Returns S, C (float32 (h, w) of the ROI), the ROI (y0, y1, x0, x1) and the
        mean depth offset (mm).
        """
        cfg = self.cfg
        items = [
            projected_quads(self.cam, self.cube, R, cfg.face_gray, cfg.ink_gray) for R in rotations
        ]
        allq = np.concatenate([q for q, _, _, _ in items])
        pad = 4
        x0 = int(max(np.floor(allq[..., 0].min()) - pad, 0))
        x1 = int(min(np.ceil(allq[..., 0].max()) + pad + 1, cfg.width_px))
        y0 = int(max(np.floor(allq[..., 1].min()) - pad, 0))
        y1 = int(min(np.ceil(allq[..., 1].max()) + pad + 1, cfg.height_px))
        S = np.zeros((max(y1 - y0, 1), max(x1 - x0, 1)), np.float32)
        C = np.zeros_like(S)
        for quads, values, covers, _ in items:
            accumulate_quads(S, C, quads, values, covers, float(x0), float(y0))
        k = 1.0 / len(items)
        if len(items) > 1:
            S *= k
            C *= k
        depth = float(np.mean([d for _, _, _, d in items]))
        return S, C, (y0, y1, x0, x1), depth

    def render(
        self,
        rotations: list[np.ndarray],
        flash: float = 0.0,
        occluded: bool = False,
    ) -> np.ndarray:
        """One frame (h, w) uint8 for the tip rotations sampled over the exposure.

        Parameters
        ----------
        rotations : list of (3, 3) arrays
            Tip rotations ``R_BT`` at sub-frame instants (one = no motion blur).
        flash : float
            Fraction of the exposure during which the sync LED was on.
        occluded : bool
            Cover this camera's marker with a dark blob (e.g. an instrument).
        """
        cfg = self.cfg
        frame = self.base.copy()
        S, C, (y0, y1, x0, x1), depth = self.scene(rotations)
        roi = frame[y0:y1, x0:x1]
        roi *= 1.0 - C
        roi += S * self.illum[y0:y1, x0:x1]
        if occluded:
            self._occlude(frame, (y0, y1, x0, x1))
        sigma = cfg.blur_sigma_px + cfg.depth_blur_px_per_mm * abs(depth)
        if sigma > 0.05:
            m = int(np.ceil(4 * sigma)) + 1
            ya, yb = max(y0 - m, 0), min(y1 + m, cfg.height_px)
            xa, xb = max(x0 - m, 0), min(x1 + m, cfg.width_px)
            sub = frame[ya:yb, xa:xb]
            frame[ya:yb, xa:xb] = cv2.GaussianBlur(
                sub, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE
            )
        if flash > 0:
            frame *= 1.0 + cfg.flash_gain * flash
        if cfg.noise_sigma > 0:
            frame += self.rng.standard_normal(frame.shape, dtype=np.float32) * np.float32(
                cfg.noise_sigma
            )
        np.clip(frame, 0, 255, out=frame)
        return np.rint(frame).astype(np.uint8)

    def _occlude(self, frame: np.ndarray, roi: tuple) -> None:
        y0, y1, x0, x1 = roi
        cx, cy = (x0 + x1) // 2, (y0 + y1) // 2
        r = int(0.45 * max(y1 - y0, x1 - x0))
        cv2.circle(frame, (cx, cy), r, 35.0, -1, lineType=cv2.LINE_AA)
