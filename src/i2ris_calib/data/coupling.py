"""Do both motors move at once, and can the recording tell coupling from hysteresis?

The fitting stage adds coupling to the other motor to its default model when the
other motor moves while this one does (docs/fit.md, "Which model"); ``diagnose``
names coupling on such recordings and says when a recording cannot separate it.

Definitions (input unit, e.g. encoder counts):

* a motor **moves** at a sample when its input changes from the previous sample by
  more than ``max(3 x input noise sd, 1e-3 x its largest |input|)``;
* the motors **move together** when the other motor moves during at least
  ``MIN_TOGETHER`` of the samples at which this one moves;
* coupling is **separable** unless the other input is (almost) a function of this
  input's level and direction of motion: when at least ``MAX_EXPLAINED`` of its
  variance is explained by those (``LEVEL_BINS`` quantile bins of this input x its
  direction), any coupling is a function of the same things as this axis's own
  hysteresis (lockstep; a single loop at one amplitude) and the fit cannot tell them
  apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.hysteresis.bands import input_noise

#: The other motor moves during at least this fraction of this one's moving samples
MIN_TOGETHER = 0.2
#: Above this fraction of the other input's variance explained by this input's level
#: and direction, coupling is not separable
MAX_EXPLAINED = 0.97
#: Quantile bins of this input's level
LEVEL_BINS = 40


@dataclass(frozen=True)
class MotorsTogether:
    """How the other motor moves with this one (module docstring).

    Attributes
    ----------
    other : str
        The other motor's axis name (``"yaw"``, ``"pitch"``) or ``"other"``.
    together : float
        Fraction of this motor's moving samples during which the other moves.
    explained : float
        Fraction of the other input's variance explained by this input's level and
        direction of motion (1: lockstep).
    """

    other: str
    together: float
    explained: float

    @property
    def moves_together(self) -> bool:
        """The other motor moves while this one does."""
        return self.together >= MIN_TOGETHER

    @property
    def separable(self) -> bool:
        """The recording can tell coupling from this axis's own hysteresis."""
        return self.explained < MAX_EXPLAINED

    @property
    def coupled(self) -> bool:
        """Fit coupling to the other motor: it moves with this one, separably."""
        return self.moves_together and self.separable

    @property
    def reason(self) -> str:
        """Why :attr:`coupled` is what it is, in a few words."""
        pct = f"{100 * self.together:.0f} %"
        if not self.moves_together:
            return f"the {self.other} motor moves in only {pct} of this motor's moving samples"
        if not self.separable:
            return (
                f"the {self.other} motor moves with this one ({pct} of its moving samples) but "
                f"in lockstep: {100 * self.explained:.1f} % of its input is a function of this "
                "input's level and direction, so coupling cannot be separated from this axis's "
                "own hysteresis (record loops of other shapes: circles and figure-eights of "
                "varying amplitude, or one motor at a time)"
            )
        return f"the {self.other} motor moves while this one does ({pct} of its moving samples)"

    @property
    def cannot_separate(self) -> bool:
        """The motors move together but the recording cannot separate coupling."""
        return self.moves_together and not self.separable

    def as_dict(self) -> dict:
        """JSON-ready form (fit.json ``model_choice.coupling``, diagnosis.json)."""
        return {"other": self.other, "together": self.together, "explained": self.explained,
                "coupled": self.coupled, "reason": self.reason}  # fmt: skip


def _moving(e: np.ndarray) -> np.ndarray:
    """bool (n,): the input changed from the previous sample beyond its noise."""
    step = np.abs(np.diff(e, prepend=e[:1]))
    peak = float(np.max(np.abs(e))) if e.size else 0.0
    return step > max(3.0 * input_noise(e), 1e-3 * peak)


def _direction(e: np.ndarray, moving: np.ndarray) -> np.ndarray:
    """+1 / -1 (n,): the sign of the last move (held samples keep it; +1 before any)."""
    d = np.where(moving, np.sign(np.diff(e, prepend=e[:1])), 0.0)
    idx = np.where(d != 0, np.arange(e.size), 0)
    idx = np.maximum.accumulate(idx)
    out = d[idx]
    return np.where(out == 0, 1.0, out)


def motors_together(
    enc: np.ndarray, enc_other: np.ndarray | None, other: str = "other"
) -> MotorsTogether | None:
    """How the other motor moves with this one (module docstring); None without it.

    Parameters
    ----------
    enc, enc_other : ndarray, shape (n,)
        This motor's and the other motor's signed inputs in time order (input unit).
    other : str
        The other motor's name, for the sentences.
    """
    if enc_other is None:
        return None
    e = np.asarray(enc, dtype=float)
    o = np.asarray(enc_other, dtype=float)
    if e.size < 4 or np.ptp(o) == 0:
        return MotorsTogether(other, 0.0, 0.0)
    mine, theirs = _moving(e), _moving(o)
    together = float((mine & theirs).sum() / max(int(mine.sum()), 1))
    edges = np.unique(np.quantile(e, np.linspace(0, 1, LEVEL_BINS + 1)[1:-1]))
    group = 2 * np.searchsorted(edges, e) + (_direction(e, mine) > 0)
    _, inv, counts = np.unique(group, return_inverse=True, return_counts=True)
    mean = np.bincount(inv, weights=o) / counts
    total = float(np.sum((o - o.mean()) ** 2))
    within = float(np.sum((o - mean[inv]) ** 2))
    explained = 1.0 - within / total if total > 0 else 0.0
    return MotorsTogether(other, together, explained)
