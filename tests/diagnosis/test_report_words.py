"""The diagnosis's words match its numbers (issue 32 item 6): "fits as well" only
within the stated criterion, no NaN in any sentence."""

from __future__ import annotations

from i2ris_calib.diagnosis.report import not_excluded_sentence
from i2ris_calib.diagnosis.results import Alternative


def alt(z: float, rms: float = 0.37) -> Alternative:
    return Alternative("backlash", 0.21, z, 0.5, False, {"width_counts": 151.0}, "", rms)


def test_not_excluded_words_follow_z_and_never_print_nan():
    assert "fits as well, held-out 0.21 deg, z = 0.5" in not_excluded_sentence([alt(0.5)])
    assert "fits better, held-out 0.21 deg, z = -6.1" in not_excluded_sentence([alt(-6.1)])
    text = not_excluded_sentence([alt(0.5, float("nan"))])
    assert "nan" not in text.lower() and "moves the angle" not in text
    assert "moves the angle by 0.37 deg RMS" in not_excluded_sentence([alt(0.5)])
