"""Exact area coverage of convex quadrilaterals on the pixel grid (numba kernel).

Each pixel ``(r, c)`` is the unit square ``[c - 0.5, c + 0.5] x [r - 0.5, r + 0.5]``
(OpenCV convention: pixel centres at integers). A pixel's value is the exact fraction
of its area covered by each polygon (box pixel response), computed by clipping the
polygon to the pixel (Sutherland-Hodgman) for pixels on an edge; pixels well inside
or outside are decided from their centre's distance to the edges. A projective map
sends the marker's square cells to exact quadrilaterals, so this renders a pinhole
view of a planar texture without sampling error.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_HALF_DIAG = 0.7072  # slightly above sqrt(2)/2


@njit(cache=True)
def _clip(px, py, n, axis, bound, keep_ge, ox, oy):
    """Clip polygon (px, py)[:n] to x|y >= bound (keep_ge) or <= bound; returns count."""
    m = 0
    for i in range(n):
        j = (i + 1) % n
        ai = px[i] if axis == 0 else py[i]
        aj = px[j] if axis == 0 else py[j]
        ini = ai >= bound if keep_ge else ai <= bound
        inj = aj >= bound if keep_ge else aj <= bound
        if ini:
            ox[m] = px[i]
            oy[m] = py[i]
            m += 1
        if ini != inj:
            t = (bound - ai) / (aj - ai)
            ox[m] = px[i] + t * (px[j] - px[i])
            oy[m] = py[i] + t * (py[j] - py[i])
            m += 1
    return m


@njit(cache=True)
def _pixel_area(qx, qy, x0, y0, ax, ay, bx, by):
    """Area of quad (qx, qy) inside the box [x0, x0+1] x [y0, y0+1]."""
    for k in range(4):
        ax[k] = qx[k]
        ay[k] = qy[k]
    n = _clip(ax, ay, 4, 0, x0, True, bx, by)
    n = _clip(bx, by, n, 0, x0 + 1.0, False, ax, ay)
    n = _clip(ax, ay, n, 1, y0, True, bx, by)
    n = _clip(bx, by, n, 1, y0 + 1.0, False, ax, ay)
    area = 0.0
    for i in range(n):
        j = (i + 1) % n
        area += ax[i] * ay[j] - ax[j] * ay[i]
    return abs(area) * 0.5


@njit(cache=True)
def accumulate_quads(S, C, quads, values, covers, x_origin, y_origin):
    """Add ``coverage * value`` of each quad to ``S`` and coverage to ``C`` (if covers).

    Parameters
    ----------
    S, C : ndarray, shape (h, w), float32
        Accumulators for a region of interest whose pixel (0, 0) is image pixel
        (y_origin, x_origin).
    quads : ndarray, shape (m, 4, 2), float64
        Convex quadrilaterals in image pixel coordinates (x, y), any orientation.
    values : ndarray, shape (m,)
        Grey value contributed per unit coverage.
    covers : ndarray, shape (m,), bool
        Whether the quad counts towards ``C`` (opaque surface) or only adds to ``S``
        (ink printed on a surface already counted).
    """
    h, w = S.shape
    qx = np.empty(4)
    qy = np.empty(4)
    ea = np.empty(4)
    eb = np.empty(4)
    ec = np.empty(4)
    scratch = (np.empty(16), np.empty(16), np.empty(16), np.empty(16))
    for q in range(quads.shape[0]):
        _inner_edges(quads[q], x_origin, y_origin, qx, qy, ea, eb, ec)
        c0 = max(0, int(np.floor(min(qx.min(), 1e9) + 0.5)))
        c1 = min(w - 1, int(np.floor(qx.max() + 0.5)))
        r0 = max(0, int(np.floor(qy.min() + 0.5)))
        r1 = min(h - 1, int(np.floor(qy.max() + 0.5)))
        _add_coverage(S, C, (r0, r1, c0, c1), values[q], covers[q], qx, qy, ea, eb, ec, scratch)


@njit(cache=True)
def _inner_edges(quad, x_origin, y_origin, qx, qy, ea, eb, ec):  # pragma: no cover - compiled
    """One quad's corners relative to the region's origin (``qx``, ``qy``) and its edge
    lines ``ea x + eb y + ec`` (unit normals pointing inside: the signed distance of a
    point to each edge, positive inside), written in place."""
    area2 = 0.0
    for k in range(4):
        qx[k] = quad[k, 0] - x_origin
        qy[k] = quad[k, 1] - y_origin
    for k in range(4):
        j = (k + 1) % 4
        area2 += qx[k] * qy[j] - qx[j] * qy[k]
    sgn = 1.0 if area2 > 0 else -1.0
    for k in range(4):
        j = (k + 1) % 4
        dx = qx[j] - qx[k]
        dy = qy[j] - qy[k]
        L = np.sqrt(dx * dx + dy * dy)
        if L == 0.0:
            L = 1e-12
        # inside is to the left for positive orientation: n = (-dy, dx)
        ea[k] = -dy / L * sgn
        eb[k] = dx / L * sgn
        ec[k] = -(ea[k] * qx[k] + eb[k] * qy[k])


@njit(cache=True)
def _add_coverage(S, C, box, val, cov, qx, qy, ea, eb, ec, scratch):  # pragma: no cover
    """Add one quad's pixel coverage x ``val`` to ``S`` (and the coverage to ``C`` when
    ``cov``) over the pixel ``box`` = (r0, r1, c0, c1): whole pixels farther inside than
    half a diagonal count 1, those farther outside 0, the rest their exact area."""
    ax, ay, bx, by = scratch
    r0, r1, c0, c1 = box
    for r in range(r0, r1 + 1):
        for c in range(c0, c1 + 1):
            dmin = 1e30
            for k in range(4):
                d = ea[k] * c + eb[k] * r + ec[k]
                if d < dmin:
                    dmin = d
            if dmin <= -_HALF_DIAG:
                continue
            if dmin >= _HALF_DIAG:
                a = 1.0
            else:
                a = _pixel_area(qx, qy, c - 0.5, r - 0.5, ax, ay, bx, by)
                if a <= 0.0:
                    continue
            S[r, c] += a * val
            if cov:
                C[r, c] += a
