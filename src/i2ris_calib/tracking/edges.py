"""Sub-pixel marker corners from the four outer edges (area-conserving edge crossings).

ArUco's ``cornerSubPix`` uses a small window around each corner and is biased by
blur at a convex corner (about 0.1-0.3 px inwards, direction dependent), which
barely moves the in-plane angle but corrupts the foreshortening that carries the
tilt. Here every pixel row (or column) crossing an outer edge of the marker gives
the exact position of the edge in that row: for a straight edge the blurred,
pixel-integrated grey values along the row sum to the sharp step's area, so

    x_cross = x_first - 0.5 + sum_i (I_i - dark) / (bright - dark)   (bright side first)

independent of the (symmetric or not) blur and of the pixel phase. A line fit
through ~0.7 * edge-length crossings per edge and the intersection of adjacent
lines give corners to a few thousandths of a pixel on a 200 px marker.

The run must stay inside the white margin around the marker and inside its black
border: on a face strongly tilted from its camera the margin is foreshortened, and
beyond it lies the cube's edge (background or a darker neighbouring face). When
the margin's (or border's) apparent width along the run, known from the
approximate corners and the marker geometry, leaves less than 3 px beyond the run,
that side of the run stops at the middle of the margin (border) and its level is
read there (pooled along the edge with a straight-line fit), not extrapolated from
the run's end with a slope: a 7 px margin otherwise moves the edge by 0.5 px
towards the bright side at 1 px blur.
"""

from __future__ import annotations

import numpy as np

#: A side of a run whose margin (border) is narrower than ``half_width + NARROW_PX``
#: along the run stops at the margin's (border's) middle, where its level is read.
NARROW_PX = 3.0


def refine_corners_by_edges(
    gray: np.ndarray,
    corners: np.ndarray,
    half_width_px: int = 6,
    span: float = 0.7,
    margin_ratio: float | None = None,
    border_ratio: float | None = None,
) -> np.ndarray | None:
    """Corners (4, 2) from line fits to the marker's outer edges, or None if unusable.

    Parameters
    ----------
    gray : ndarray (h, w) uint8
        The frame.
    corners : ndarray (4, 2)
        Approximate corners (px) in ArUco order (clockwise from top-left).
    half_width_px : int
        Pixels on each side of the edge in every row/column integral; must exceed
        about 3 blur sigmas and stay inside the marker's black border and the white
        margin around it.
    span : float
        Central fraction of each edge used (keeps away from the corners).
    margin_ratio : float, optional
        Width of the white margin around the marker / the marker's edge length
        (``(cube - marker) / (2 marker)`` for a marker centred on a cube face).
        None: the margin is assumed wider than the runs (no adaptation).
    border_ratio : float, optional
        Width of the black border / the marker's edge length (1 / cells, e.g. 1/6
        for a 4x4 dictionary). None: assumed wider than the runs.
    """
    c = np.asarray(corners, dtype=float)
    centre = c.mean(axis=0)
    lines = []
    for k in range(4):
        p0, p1 = c[k], c[(k + 1) % 4]
        # the marker's apparent extent across this edge: the far corners' distance
        d = p1 - p0
        nrm = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-9)
        depth = float(np.mean(np.abs((c[[(k + 2) % 4, (k + 3) % 4]] - p0) @ nrm)))
        widths = (
            None if margin_ratio is None else margin_ratio * depth,
            None if border_ratio is None else border_ratio * depth,
        )
        line = _edge_line(gray, p0, p1, centre, half_width_px, span, widths)
        if line is None:
            return None
        lines.append(line)
    out = np.empty((4, 2))
    for k in range(4):
        p = _intersect(lines[(k - 1) % 4], lines[k])
        if p is None:
            return None
        out[k] = p
    if np.max(np.abs(out - c)) > 3.0:  # refinement must stay near the detection
        return None
    return out


def _edge_line(gray, p0, p1, centre, hw, span, widths=(None, None)):
    """Line (point, unit direction) fitted to the crossings of edge p0 -> p1.

    ``widths``: (white margin, black border) widths perpendicular to the edge (px) or
    None; a side narrower than ``hw + NARROW_PX`` along the run is cut at its middle.
    """
    h, w = gray.shape
    d = p1 - p0
    vertical = abs(d[1]) >= abs(d[0])
    a, b = (1, 0) if vertical else (0, 1)  # a: coordinate stepped per row, b: along the run
    lo, hi = sorted((p0[a], p1[a]))
    mid, half = (lo + hi) / 2.0, (hi - lo) * span / 2.0
    steps = np.arange(int(np.ceil(mid - half)), int(np.floor(mid + half)) + 1)
    if steps.size < 5:
        return None
    # along-run position of the approximate edge at each row
    pos = p0[b] + (steps - p0[a]) * d[b] / d[a]
    # along-run extent of each side: hw, or half the margin / border when narrow
    cos_run = abs(d[a]) / max(float(np.hypot(*d)), 1e-9)  # |edge normal . run direction|
    n_side = []
    for width in widths:
        along = np.inf if width is None else width / max(cos_run, 1e-9)
        n_side.append(hw if along >= hw + NARROW_PX else int(max(2, np.floor(along / 2.0))))
    nb, nd = n_side
    if nb < hw or nd < hw:
        # short runs must be centred on the edge: locate it with full runs first
        first = _edge_line(gray, p0, p1, centre, hw, span)
        if first is None:
            return None
        m, u = first
        if abs(u[a]) < 1e-9:
            return None
        pos = m[b] + (steps - m[a]) * u[b] / u[a]
    # the marker (dark) lies towards the centre; runs are oriented bright -> dark
    inner_high = centre[b] > np.mean(pos)
    lo_n, hi_n = (nb, nd) if inner_high else (nd, nb)
    start = np.rint(pos).astype(int) - lo_n
    runs = start[:, None] + np.arange(lo_n + hi_n + 1)[None, :]
    limit = w if vertical else h
    ok = (runs[:, 0] >= 0) & (runs[:, -1] < limit) & (steps >= 0) & (steps < (h if vertical else w))
    if ok.sum() < 5:
        return None
    steps, start, runs = steps[ok], start[ok], runs[ok]
    vals = gray[steps[:, None], runs] if vertical else gray[runs, steps[:, None]]
    vals = vals.astype(float)
    if not inner_high:
        vals = vals[:, ::-1]
    norm, good = _normalised(vals, steps, nb < hw, nd < hw)
    if good.sum() < 5:
        return None
    s = norm.sum(axis=1)
    cross = (start[good] - 0.5 + s) if inner_high else (runs[good, -1] + 0.5 - s)
    pts = np.empty((good.sum(), 2))
    pts[:, a] = steps[good]
    pts[:, b] = cross
    return _fit_line(pts)


def _normalised(vals: np.ndarray, steps=None, plateau_bright=False, plateau_dark=False):
    """(I - dark) / (bright - dark) per pixel for runs (m, k) ordered bright -> dark.

    Bright and dark levels are the means of the three end pixels of each run,
    extrapolated along the run with the slope pooled over all runs of the edge:
    uneven illumination (a linear ramp across the edge) then biases nothing.
    ``plateau_bright`` / ``plateau_dark`` (a side cut at the middle of a narrow margin
    or border): that level is the run's end pixel, smoothed along the edge by a
    straight-line fit over ``steps`` (m,) and held constant along the run (the end
    pixels there are not a flat stretch from which a slope could be read).
    """
    k = vals.shape[1]
    x = np.arange(k, dtype=float)
    if plateau_bright:
        bright = _pooled(vals[:, 0], steps)[:, None] + 0.0 * x[None, :]
    else:
        slope_b = float(np.mean(vals[:, 2] - vals[:, 0]) / 2.0)
        bright = vals[:, :3].mean(axis=1)[:, None] + slope_b * (x - 1.0)[None, :]
    if plateau_dark:
        dark = _pooled(vals[:, -1], steps)[:, None] + 0.0 * x[None, :]
    else:
        slope_d = float(np.mean(vals[:, -1] - vals[:, -3]) / 2.0)
        dark = vals[:, -3:].mean(axis=1)[:, None] + slope_d * (x - (k - 2.0))[None, :]
    contrast = bright - dark
    good = contrast.min(axis=1) > 10.0
    return ((vals - dark) / np.where(contrast > 1e-6, contrast, 1.0))[good], good


def _pooled(level: np.ndarray, steps) -> np.ndarray:
    """Straight-line fit of a level (m,) over the row/column index ``steps`` (m,)."""
    if steps is None or len(level) < 3:
        return np.full(len(level), float(np.mean(level)))
    s = np.asarray(steps, dtype=float)
    return np.polyval(np.polyfit(s - s.mean(), level, 1), s - s.mean())


def _fit_line(pts: np.ndarray):
    """Total-least-squares line with one round of 3.5-MAD outlier rejection."""
    for _ in range(2):
        m = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - m, full_matrices=False)
        direction, normal = vt[0], vt[1]
        res = (pts - m) @ normal
        mad = np.median(np.abs(res - np.median(res))) * 1.4826 + 1e-9
        keep = np.abs(res) <= 3.5 * mad + 1e-6
        if keep.all() or keep.sum() < 5:
            break
        pts = pts[keep]
    return m, direction


def _intersect(l1, l2):
    (p, u), (q, v) = l1, l2
    A = np.array([u, -v]).T
    if abs(np.linalg.det(A)) < 1e-9:
        return None
    s = np.linalg.solve(A, q - p)
    return p + s[0] * u
