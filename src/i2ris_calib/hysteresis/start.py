"""Data-driven starts of GPI/EGPI fits (``model.guess``; LM alone from a poor start fails).

Recipe (docs/fit.md):

1. Shape parameters ``sigma, r1, rn, kappa`` from the angle range Theta:
   ``rn = 0.1 Theta``, ``r1 = 0.1 rn``, ``sigma = 0.5 / rn``, ``kappa = 4``; ``lam`` so
   that the operator weights sum to 1 (lam and the envelope scale are exactly
   redundant, see docs/models.md, so lam is held fixed by default).
2. Envelope lines from the branches: with weights summing to P and
   ``pr = sum p_i r_i``, a long loading stretch follows ``P (a1 v + a2) - pr``, a long
   unloading stretch above the flag point ``P (a3 v + a4) + pr`` and below it
   ``P (a5 v + a6) + kappa pr``; straight-line fits give a1..a6: loading and upper
   unloading samples far (>= 20 % of the input range) from the last reversal, lower
   unloading samples in the lower half of their angles (below the S3 dead zone);
   samples within 5 % of the range of the estimated flag point are left out.
3. Flag point (:func:`flag_point`): on each unloading stretch, the first input value
   from which the angle stops following the input (|d theta / d v| below 20 % of the
   loading slope, read over the next 6 % of the range) after it has followed it - the
   paper's "first point where the derivative is approximately zero" (Lee et al. 2021),
   read as the derivative of the output with respect to the input, since the commanded
   input itself keeps moving. Two readings are started from
   (:func:`flag_point_candidates`): the slope between neighbouring bins (the start and
   the spread below), and over 6 % of the range (one more data-driven start).
4. Further starts: the shape parameters spread by a seeded scrambled Halton design
   (:func:`start_values`), the envelope lines refitted for each.

The recipe applies to models whose parameters are exactly those of the GPI
(:data:`GPI_PARAMETERS`) or of the I2RIS EGPI (:data:`EGPI_PARAMETERS`, both the
paper's and the continuous variant); any other model keeps its values. It lives with
the models (``ParametricModel.guess``) and is used by the fitting stage.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from i2ris_calib.hysteresis.bands import input_bands
from i2ris_calib.hysteresis.kernel import density, motion_direction, thresholds
from i2ris_calib.model import Model

#: Parameters of the models the recipe applies to (model order)
GPI_PARAMETERS = ("a1", "a2", "a3", "a4", "lam", "sigma", "r1", "rn")
EGPI_PARAMETERS = ("a1", "a2", "a3", "a4", "a5", "a6", "lam", "sigma", "r1", "rn", "kappa", "v_f")


def recipe_of(model: Model) -> str | None:
    """``"gpi"``, ``"egpi"`` (both EGPI variants) or None: which start recipe applies."""
    names = tuple(p.name for p in model.parameters)
    return {GPI_PARAMETERS: "gpi", EGPI_PARAMETERS: "egpi"}.get(names)


def default_deadband(v: np.ndarray) -> float:
    """The ``v'`` dead band derived from the input
    (:func:`i2ris_calib.hysteresis.bands.input_bands`), what the fit uses unless configured."""
    return input_bands(np.asarray(v, dtype=float)).deadband


def keep_fixed(model: Model, x: np.ndarray) -> np.ndarray:
    """Start ``x`` (shape (p,)) with the fixed parameters at the model's values, except
    ``lam`` (the scale gauge, set by the recipe), ``v_f`` (estimated from the data) and
    ``r_max`` (the threshold grid of the signed PI model, set from the input range)."""
    x = np.array(x, dtype=float)
    for i, p in enumerate(model.parameters):
        if p.fixed and p.name not in ("lam", "v_f", "r_max"):
            x[i] = p.value
    return x


def segments(direction: np.ndarray) -> np.ndarray:
    """Index of the monotone stretch every sample belongs to, int (n,)."""
    d = np.asarray(direction)
    return np.concatenate(([0], np.cumsum(d[1:] != d[:-1])))


def reversal_distance(v: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """|v - v at the start of the current monotone stretch| (counts), shape (n,)."""
    seg = segments(direction)
    starts = np.flatnonzero(np.concatenate(([True], seg[1:] != seg[:-1])))
    anchor = np.asarray(v, dtype=float)[starts][seg]
    return np.abs(np.asarray(v, dtype=float) - anchor)


def _line(v: np.ndarray, theta: np.ndarray, sel: np.ndarray, min_samples: int = 5):
    """(slope, intercept) of a straight line through the selected samples, or None.

    Least squares, then once more without the samples beyond 3 robust sd (1.4826 MAD)
    of the residuals: tracking outliers do not tilt the start.
    """
    sel = sel & np.isfinite(theta)
    if sel.sum() < min_samples or np.ptp(v[sel]) <= 0:
        return None
    slope, intercept = _least_squares_line(v[sel], theta[sel])
    res = theta[sel] - (slope * v[sel] + intercept)
    scale = 1.4826 * np.median(np.abs(res - np.median(res)))
    keep = np.abs(res) <= 3.0 * scale if scale > 0 else np.ones(res.size, bool)
    if min_samples <= keep.sum() < res.size and np.ptp(v[sel][keep]) > 0:
        slope, intercept = _least_squares_line(v[sel][keep], theta[sel][keep])
    return float(slope), float(intercept)


def _least_squares_line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(slope, intercept) of the least-squares line y = slope x + intercept.

    Solved about the mean of ``x``, so inputs far from zero with a small spread (a
    short stretch at 5,000 counts) are well conditioned, unlike a Vandermonde fit
    (``np.polyfit`` warned there). ``x`` must not be constant.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    xm, ym = float(x.mean()), float(y.mean())
    dx = x - xm
    slope = float(dx @ (y - ym)) / float(dx @ dx)
    return slope, ym - slope * xm


def _trimmed_mean(x: np.ndarray) -> float:
    """Mean of ``x`` without values beyond 3 robust sd (1.4826 MAD) of its median."""
    med = np.median(x)
    scale = 1.4826 * np.median(np.abs(x - med))
    keep = np.abs(x - med) <= 3.0 * scale if scale > 0 else np.ones(x.size, bool)
    return float(np.mean(x[keep])) if keep.any() else float(med)


#: :func:`flag_point` estimates from the unloading stretches that start in the top
#: this share of the input range, when there are any.
FLAG_TOP_SHARE = 0.9
#: :func:`flag_point` reads the slope from each input bin over this many bins (2 % of
#: the range each) further down.
FLAG_RUN = 3
#: The secant lengths :func:`flag_point` tries in turn (bins).
FLAG_RUNS = tuple(range(FLAG_RUN, 0, -1))


def flag_point(
    v: np.ndarray,
    theta: np.ndarray,
    direction: np.ndarray,
    loading_slope: float | None = None,
    runs: tuple[int, ...] = FLAG_RUNS,
) -> float | None:
    """Flag point v_f (counts) estimated from the unloading stretches, or None.

    Per unloading stretch covering >= 30 % of the input range, theta is averaged
    (without values beyond 3 robust sd of the bin's median) in input bins of 2 % of the
    range, and v_f is the first bin (walking down in v) from which the angle stays flat,
    |d theta/d v| < 0.2 |loading slope|, after it has moved, |d theta/d v| >
    0.5 |loading slope| - the slope read from each bin to the bin :data:`FLAG_RUN` (3)
    further down, a secant over 6 % of the range, so one noisy bin mean cannot trip
    (or miss) it: the flag point is where, unloading from above it, the angle stops
    changing over a stretch. A stretch with no flat part that long is read with a
    secant over 2 bins, then over 1 (:func:`_flat_after_moving`). Measured on egpi_c:4
    of bench_optimum (paper protocol, 500 Hz, n=19,243, noise 0.45 deg): with the
    slope between neighbouring bins, a noisy bin just below the top of both full-scale
    stretches read 0.19 x the loading slope between 0.69 and 0.62, the estimate 4,916
    against the truth's 3,558, the fit ended at 1.082x the truth's cost; with the
    secant 3,619 and 0.9991x. Over the 400 cases egpi and egpi_c 0-199 the estimate
    was more than 10 % of the range off on 56 with neighbouring bins, on 4 with the
    secant.
    The median over stretches is returned, over those that come down from the top
    :data:`FLAG_TOP_SHARE` of the range when there are any: the flag point shows only
    on unloading from above it, so a stretch that turned below it gives a spurious
    estimate (measured on egpi:153 of bench_optimum, paper protocol at 5 Hz: stretches
    from 1,836 and 1,253 counts gave 1,623 and 1,133, the two from full scale 2,603
    and 1,868; the median of all 1,745 against the truth's 2,107, the fit ended at
    9.8x the truth's cost; from the two, 2,235 and 0.976x).

    ``runs``: the secant lengths (bins) tried in turn; ``(1,)`` reads the slope between
    neighbouring bins only (the second candidate of :func:`flag_point_candidates`).
    """
    v = np.asarray(v, dtype=float)
    theta = np.asarray(theta, dtype=float)
    span = float(np.ptp(v))
    if span <= 0:
        return None
    if loading_slope is None:
        line = _line(v, theta, direction > 0)
        if line is None:
            return None
        loading_slope = line[0]
    s_ref = abs(loading_slope)
    width = 0.02 * span
    seg = segments(direction)
    found, top = [], []
    for s in np.unique(seg[direction < 0]):
        sel = (seg == s) & np.isfinite(theta)
        if sel.sum() < 10 or np.ptp(v[sel]) < 0.3 * span:
            continue
        high = float(np.max(v[sel])) >= float(v.min()) + FLAG_TOP_SHARE * span
        vb = np.floor((v[sel] - v.min()) / width).astype(int)
        counts = np.bincount(vb)
        keep = counts > 0
        centres = (np.arange(counts.size)[keep] + 0.5) * width + v.min()
        th_sel = theta[sel]
        # trimmed bin means: a tracking outlier does not fake a slope change
        means = np.array([_trimmed_mean(th_sel[vb == b]) for b in np.flatnonzero(keep)])
        # walk from high v to low v
        c, m = centres[::-1], means[::-1]
        vf = _flat_after_moving(c, m, s_ref, runs)
        if vf is not None:
            found.append(vf)
            if high:
                top.append(vf)
    found = top or found
    return float(np.median(found)) if found else None


def _flat_after_moving(
    c: np.ndarray, m: np.ndarray, s_ref: float, runs: tuple[int, ...] = FLAG_RUNS
) -> float | None:
    """The first bin centre ``c`` (descending, counts) from which the angle ``m`` (bin
    means) stays flat, |slope| < 0.2 ``s_ref``, after it has moved, |slope| > 0.5
    ``s_ref``; None when it never does. The slope is read from each bin to the bin
    ``runs[0]`` further down, then the next of ``runs`` when no flat stretch is that
    long."""
    for k in runs:
        if c.size <= k:
            continue
        slope = np.abs((m[k:] - m[:-k]) / (c[k:] - c[:-k]))
        moving = np.flatnonzero(slope > 0.5 * s_ref)
        if moving.size == 0:
            continue
        after = np.flatnonzero((slope < 0.2 * s_ref) & (np.arange(slope.size) > moving[0]))
        if after.size:
            return float(c[after[0]])
    return None


#: A second flag-point start (:func:`flag_point_candidates`) is made when the two
#: readings differ by more than this share of the input range.
FLAG_CANDIDATE_GAP = 0.02


def flag_point_candidates(v: np.ndarray, theta: np.ndarray, deadband: float = 0.0) -> list[float]:
    """Flag points (counts) an EGPI fit starts from: the reading with the slope between
    neighbouring bins (:func:`flag_point` with ``runs=(1,)``: the data-driven start and
    the spread of shape starts around it), then the secant's over :data:`FLAG_RUN` bins
    (:func:`flag_point`'s default: one more data-driven start) when it differs by more
    than :data:`FLAG_CANDIDATE_GAP` of the range; empty when neither finds one.

    The secant is the better estimate (over bench_optimum's egpi and egpi_c seeds
    0-199 more than 10 % of the range off on 4 of 400 cases, against 56), yet the
    better basin is not always reached from the nearer flag point: with the secant
    as the first start, egpi:49, egpi:63 and egpi:100 (paper protocol mid-loop, 5 Hz,
    n = 305-663, noise 0.36-0.46 deg) ended at 3.42x, 8.79x and 2.77x the truth's cost
    against 0.958x, 0.995x and 0.949x with the neighbouring-bin reading first; egpi_c:4 the
    other way round (1.082x from the neighbouring-bin reading, 0.9991x with the secant
    as one more start). Both are started from, the neighbouring-bin reading first so
    that every start it had is kept.
    """
    v = np.asarray(v, dtype=float)
    theta = np.asarray(theta, dtype=float)
    direction = motion_direction(np.ascontiguousarray(v), float(deadband))
    out = []
    for runs in ((1,), FLAG_RUNS):
        vf = flag_point(v, theta, direction, runs=runs)
        gap = FLAG_CANDIDATE_GAP * float(np.ptp(v))
        if vf is not None and all(abs(vf - x) > gap for x in out):
            out.append(vf)
    return out


def shape_defaults(theta: np.ndarray) -> dict[str, float]:
    """Default shape parameters from the angle range (step 1 of the recipe)."""
    span = float(np.nanmax(theta) - np.nanmin(theta)) if np.isfinite(theta).any() else 1.0
    rn = max(0.1 * span, 1e-3)
    return {"sigma": 0.5 / rn, "r1": 0.1 * rn, "rn": rn, "kappa": 4.0}


def envelope_values(
    model: Model,
    v: np.ndarray,
    theta: np.ndarray,
    direction: np.ndarray,
    shape: dict[str, float],
    v_f: float | None,
) -> dict[str, float]:
    """a1..a6 (as the model has them) and lam from branch lines, given shape params."""
    r = thresholds(shape["r1"], shape["rn"], int(model.n))
    lam = 1.0 / np.exp(-shape["sigma"] * r).sum()
    p = density(r, lam, shape["sigma"])
    P, pr = float(p.sum()), float((p * r).sum())
    span = float(np.ptp(v))
    far = reversal_distance(v, direction) > 0.2 * span
    up, down = direction > 0, direction < 0
    load = (
        _line(v, theta, up & far) or _line(v, theta, up) or (np.nanmax(theta) / max(span, 1), 0.0)
    )
    out = {"lam": lam, "a1": load[0] / P, "a2": (load[1] + pr) / P}
    margin = 0.05 * span  # keep clear of the (uncertain) flag point
    upper = down & (v > v_f + margin) if v_f is not None else down
    unl1 = _line(v, theta, upper & far) or _line(v, theta, upper) or (load[0], load[1] + 2 * pr)
    out.update(a3=unl1[0] / P, a4=(unl1[1] - pr) / P)
    if recipe_of(model) == "egpi":
        kappa = shape["kappa"]
        vlow = v_f if v_f is not None else float(np.median(v))
        lower = down & (v <= vlow - margin)
        # the steep part below the stage-2 dead zone: the lower half of those angles
        ok = lower & np.isfinite(theta)
        low_half = ok & (theta <= np.median(theta[ok])) if ok.any() else ok
        unl2 = _line(v, theta, low_half) or _line(v, theta, lower) or unl1
        out.update(a5=unl2[0] / P, a6=(unl2[1] - kappa * pr) / P)
    return out


def initial_values(
    model: Model,
    v: np.ndarray,
    theta: np.ndarray,
    deadband: float = 0.0,
    shape: dict[str, float] | None = None,
    v_f: float | None = None,
) -> np.ndarray:
    """Data-driven start vector for ``model`` (GPI or I2RIS EGPI), shape (p,).

    Other model types get their current values. Fixed parameters keep their values
    except ``lam`` (set by the normalisation of step 1 unless the caller fixed a
    value through ``shape``) and ``v_f`` (estimated when ``v_f`` is None and the
    model's value is not pinned).
    """
    recipe = recipe_of(model)
    if recipe is None:
        return np.array([p.value for p in model.parameters], dtype=float)
    v = np.asarray(v, dtype=float)
    theta = np.asarray(theta, dtype=float)
    direction = motion_direction(np.ascontiguousarray(v), float(deadband))
    sh = shape_defaults(theta) | (shape or {})
    vals = {k: sh[k] for k in ("sigma", "r1", "rn")}
    if recipe == "egpi":
        if v_f is None:
            found = flag_point_candidates(v, theta, deadband)
            v_f = found[0] if found else None
        if v_f is None:
            v_f = float(np.min(v) + 0.6 * np.ptp(v))
        vals.update(kappa=sh["kappa"], v_f=v_f)
    vals.update(envelope_values(model, v, theta, direction, sh, vals.get("v_f")))
    if "lam" in sh:
        vals["lam"] = sh["lam"]
    return model.vector({k: x for k, x in vals.items() if k in model.names})


#: Spread of the shape starts: factors in [1/SHAPE_SPREAD, SHAPE_SPREAD] of the
#: data-driven rn, r1 and sigma (:func:`start_values`).
SHAPE_SPREAD = 4.0
#: Range of kappa over the starts (:func:`start_values`).
KAPPA_RANGE = (1.0, 16.0)


def start_values(
    model: Model,
    v: np.ndarray,
    theta: np.ndarray,
    n_starts: int,
    rng: np.random.Generator,
    deadband: float = 0.0,
    v_f: float | None = None,
) -> list[np.ndarray]:
    """``n_starts`` start vectors: the data-driven one first, then variations of the
    shape parameters spread over the space labs see: a scrambled Halton design (seeded
    by ``rng``) over log factors in [1/4, 4] of the data-driven ``rn``, ``r1`` and
    ``sigma`` and ``kappa`` log-uniform in [1, 16] (an EGPI's second family can be
    from about as steep as the first to many times steeper). A design covers the box
    evenly where random draws cluster (measured on the README demo's pitch+: the
    best EGPI basin, 12x lower in cost than the data-driven start's, is reached from
    about one start in five)."""
    base = shape_defaults(np.asarray(theta, dtype=float))
    extra = []
    if recipe_of(model) == "egpi" and v_f is None:
        found = flag_point_candidates(v, theta, deadband)
        if found:
            v_f, extra = found[0], found[1:]
    starts = [initial_values(model, v, theta, deadband, base, v_f)]
    if recipe_of(model) == "egpi":
        v_f = float(starts[0][EGPI_PARAMETERS.index("v_f")])
    if n_starts > 1:
        u = qmc.Halton(d=4, scramble=True, rng=rng).random(n_starts - 1)
        f = np.exp(np.log(SHAPE_SPREAD) * (2.0 * u[:, :3] - 1.0))
        kappa = np.exp(np.log(KAPPA_RANGE[0]) + u[:, 3] * np.log(KAPPA_RANGE[1] / KAPPA_RANGE[0]))
        for fi, ki in zip(f, kappa, strict=True):
            shape = {
                "rn": base["rn"] * fi[0],
                "r1": base["r1"] * fi[1],
                "sigma": base["sigma"] * fi[2],
                "kappa": float(ki),
            }
            starts.append(initial_values(model, v, theta, deadband, shape, v_f))
    # the other flag-point reading: one more data-driven start, last
    # (:func:`flag_point_candidates`)
    starts += [initial_values(model, v, theta, deadband, base, x) for x in extra]
    return starts
