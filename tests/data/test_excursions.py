"""Excursions about zero: the signed-vs-split choice says when it hinges on a handful
of excursions (issue 32 item 5)."""

from __future__ import annotations

import numpy as np

from i2ris_calib.data.excursions import excursions


def ramps(n_excursions: int, fast_at: tuple[int, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
    """Excursions alternating in sign, each starting after a 1 s rest at zero (30 Hz),
    except those in ``fast_at``, which start straight from the previous one."""
    parts = []
    for i in range(n_excursions):
        sign = 1 if i % 2 == 0 else -1
        if i not in fast_at:
            parts.append(np.zeros(30))
        parts.append(sign * np.r_[np.linspace(0, 3000, 60), np.linspace(3000, 0, 60)[1:-1]])
    enc = np.concatenate(parts)
    return enc, np.arange(enc.size) / 30.0


def test_one_crossing_among_many_rests_is_marginal_and_says_which_way():
    enc, t = ramps(10, fast_at=(5,))
    ex = excursions(enc, 5.0, t)
    assert ex.signed and ex.n_crossings == 1
    assert "hinges on 1 of 10 excursions" in ex.reason and "--split" in ex.reason
    enc, t = ramps(10, fast_at=tuple(range(1, 10)))  # crossing every time: not marginal
    ex = excursions(enc, 5.0, t)
    assert ex.signed and ex.marginal == "" and "hinges" not in ex.reason
    enc, t = ramps(10)  # the paper's protocol: split, nothing to warn
    ex = excursions(enc, 5.0, t)
    assert not ex.signed and ex.marginal == ""
