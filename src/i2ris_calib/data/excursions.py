"""How a recording drives an axis: excursions from zero, rests, zero crossings.

The fitting stage chooses its default model from this (docs/fit.md, "Which model"):
the paper's protocol moves one motor at a time, each excursion starting at rest at
zero, and is fitted per motion direction; a recording whose input crosses zero (both
tendons in turn, no rest between) or whose excursions do not start at rest is fitted
with one model of the axis over its whole signed input (the two-tendon GPI).

Definitions (input unit, e.g. encoder counts):

* an **excursion** is a run of samples outside the zero band (``|enc| > zero_band``)
  on one side of zero whose peak |enc| is at least ``SUBSTANTIAL`` of the recording's
  largest |enc| (smaller runs count as "near zero");
* a **rest** before an excursion is at least ``REST_SAMPLES`` samples near zero
  lasting at least ``REST_S`` seconds (or the whole stretch before the first
  excursion when the recording starts near zero with such a rest);
* a **zero crossing** is an excursion that follows one of the other sign without a
  rest between them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: An excursion's peak must reach this fraction of the largest |input| to count
SUBSTANTIAL = 0.1
#: The signed input chosen on at most this many odd excursions (crossing zero or not
#: starting at rest), and at most a fifth of them, is flagged as marginal
MARGINAL_EXCURSIONS = 2
#: A rest lasts at least this many samples ...
REST_SAMPLES = 3
#: ... and at least this long (s)
REST_S = 0.25


@dataclass(frozen=True)
class Excursions:
    """How an input moves about zero (module docstring).

    Attributes
    ----------
    n_excursions : int
        Substantial excursions.
    n_positive, n_negative : int
        Of those, on the positive / negative side.
    n_from_rest : int
        Excursions that start after a rest at zero.
    n_crossings : int
        Excursions that follow one of the other sign without a rest (zero crossings).
    """

    n_excursions: int
    n_positive: int
    n_negative: int
    n_from_rest: int
    n_crossings: int

    @property
    def both_sides(self) -> bool:
        """Both tendons move: substantial excursions on both sides of zero."""
        return self.n_positive > 0 and self.n_negative > 0

    @property
    def signed(self) -> bool:
        """True when one model over the whole signed input fits this recording: both
        sides move, and the input crosses zero or an excursion does not start at rest."""
        return self.both_sides and (self.n_crossings > 0 or self.n_from_rest < self.n_excursions)

    @property
    def reason(self) -> str:
        """Why :attr:`signed` is what it is, in a few words."""
        if not self.both_sides:
            return "the input stays on one side of zero"
        if not self.signed:
            return (
                f"each of the {self.n_excursions} excursions starts at rest at zero, one "
                "side at a time"
            )
        parts = []
        if self.n_crossings:
            parts.append(
                f"the input crosses zero {self.n_crossings} "
                f"time{'s' if self.n_crossings != 1 else ''}"
            )
        not_rest = self.n_excursions - self.n_from_rest
        if not_rest:
            parts.append(
                "excursions do not start at rest"
                if not_rest == self.n_excursions
                else f"{not_rest} of {self.n_excursions} excursions do not start at rest"
            )
        text = "; ".join(parts)
        if self.marginal:
            text += f" ({self.marginal})"
        return text

    @property
    def marginal(self) -> str:
        """A warning when the signed-vs-split choice hinges on a few excursions: signed
        because at most :data:`MARGINAL_EXCURSIONS` (and at most a fifth) of them cross
        zero or start away from rest; empty otherwise."""
        if not self.signed:
            return ""
        odd = max(self.n_crossings, self.n_excursions - self.n_from_rest)
        if odd > MARGINAL_EXCURSIONS or odd > 0.2 * self.n_excursions:
            return ""
        return (
            f"warning: the choice hinges on {odd} of {self.n_excursions} excursions; the "
            f"other {self.n_excursions - odd} start at rest at zero, as in the paper's "
            f"protocol. A rest needs {REST_SAMPLES} samples and {REST_S} s inside the zero "
            "band: a ramp passing zero faster looks like a crossing. Fit --split to keep "
            "a recording of the same protocol on the paper's split"
        )


def excursions(enc: np.ndarray, zero_band: float, time_s: np.ndarray | None = None) -> Excursions:
    """Count the excursions, rests and zero crossings of an axis's signed input.

    Parameters
    ----------
    enc : ndarray, shape (n,)
        The axis's signed input in time order (input unit).
    zero_band : float
        ``|enc| <= zero_band`` is near zero (input unit; ``Dataset.bands.zero_band``).
    time_s : ndarray, shape (n,), optional
        Sample times (s); without them a rest is ``REST_SAMPLES`` samples.
    """
    e = np.asarray(enc, dtype=float)
    side = np.where(e > zero_band, 1, np.where(e < -zero_band, -1, 0))
    peak = float(np.max(np.abs(e))) if e.size else 0.0
    edges = np.flatnonzero(np.diff(side)) + 1
    starts = np.concatenate(([0], edges))
    ends = np.concatenate((edges, [e.size]))
    runs = [
        (int(side[a]), a, b)
        for a, b in zip(starts, ends, strict=True)
        if side[a] != 0 and np.max(np.abs(e[a:b])) >= SUBSTANTIAL * peak
    ]
    n_rest = n_cross = 0
    prev_sign, prev_end = 0, 0
    for sign, a, b in runs:
        gap = a - prev_end  # samples near zero before this excursion
        rest = gap >= REST_SAMPLES and (
            time_s is None or time_s[a - 1] - time_s[prev_end] >= REST_S
        )
        n_rest += int(rest)
        n_cross += int(not rest and prev_sign == -sign)
        prev_sign, prev_end = sign, b
    pos = sum(1 for s, _, _ in runs if s > 0)
    return Excursions(len(runs), pos, len(runs) - pos, n_rest, n_cross)
