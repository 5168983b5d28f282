"""Number formatting of the report: ``value ± stderr`` with the digits the uncertainty supports."""

from __future__ import annotations

import math
import re

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from i2ris_calib.report.tables import DASH, fmt_pm, fmt_sig, short_meaning

PM = re.compile(r"^(?P<v>-?\d+(\.\d+)?) ± (?P<s>\d+(\.\d+)?)(?P<tail> \(not identified\))?$")
PM_EXP = re.compile(
    r"^\((?P<v>-?\d+(\.\d+)?) ± (?P<s>\d+(\.\d+)?)\)e(?P<e>-?\d+)(?P<tail> \(not identified\))?$"
)


@pytest.mark.parametrize(
    ("value", "stderr", "text"),
    [
        (3.49926e-05, 0.163169, "0.00003 ± 0.16 (not identified)"),  # the example
        (0.00590275883368193, 7.978e-05, "0.005903 ± 0.000080"),
        (4224.8, 31.2, "4225 ± 31"),
        (123456.0, 5634.0, "123500 ± 5600"),
        (-8.563742613843036, 0.243, "-8.56 ± 0.24"),
        (0.5, 0.0996, "0.50 ± 0.10"),  # rounding the stderr up adds a digit: one place fewer
        (3e-9, 1e-10, "(3.00 ± 0.10)e-9"),
        (2.5e7, 3.3e5, "(2.500 ± 0.033)e7"),
        (-0.0001, 0.5, "-0.0001 ± 0.50 (not identified)"),
    ],
)
def test_fmt_pm_known_cases(value, stderr, text):
    assert fmt_pm(value, stderr) == text


def test_fmt_pm_words_for_fixed_missing_and_unidentified():
    assert fmt_pm(0.0364, 0.0, fixed=True) == "0.0364 (fixed)"
    assert fmt_pm(4224.83, None, no_stderr="profiled") == "4225 (profiled)"
    assert fmt_pm(0.2, float("nan")) == "0.2 (not identified)"
    assert fmt_pm(None, 0.1) == fmt_pm(float("nan"), 0.1) == DASH
    assert fmt_pm(1.0, 2.0).endswith("(not identified)")
    assert not fmt_pm(2.0, 1.0).endswith("(not identified)")
    assert fmt_sig(4224.83) == "4225" and fmt_sig(1e-9) == "1.000e-09" and fmt_sig(None) == DASH


def _parse(text: str) -> tuple[float, float, int, bool]:
    """(value, stderr, decimals of the printed stderr, not-identified flag)."""
    m = PM.match(text)
    if m:
        scale = 1.0
    else:
        m = PM_EXP.match(text)
        assert m, text
        scale = 10.0 ** int(m.group("e"))
    s_txt = m.group("s")
    decimals = len(s_txt.split(".")[1]) if "." in s_txt else 0
    return float(m.group("v")) * scale, float(s_txt) * scale, decimals, bool(m.group("tail"))


values = st.floats(min_value=-1e9, max_value=1e9, allow_nan=False).filter(
    lambda x: x == 0 or abs(x) > 1e-12
)
stderrs = st.floats(min_value=1e-11, max_value=1e9, allow_nan=False)


@settings(max_examples=400, deadline=None)
@given(values, stderrs)
def test_fmt_pm_properties(value, stderr):
    assume(stderr > 1e-8 * abs(value))  # within float64's digits
    text = fmt_pm(value, stderr)
    v, s, _, tail = _parse(text)
    # the stderr keeps 2 significant digits (within rounding)
    place = 10.0 ** (math.floor(math.log10(stderr)) - 1)
    assert abs(s - stderr) <= 0.5 * place * 1.0001 + 1e-300 or abs(s - stderr) <= 0.05 * stderr
    # the value is shown to the stderr's decimal place (or, when that rounds it to zero,
    # to one significant digit): never off by more than half that place
    unit = 10.0 ** (math.floor(math.log10(s)) - 1) if s > 0 else place
    assert abs(v - value) <= 0.5 * unit * 1.001 or (
        abs(value) < unit and abs(v - value) <= 0.5 * 10.0 ** math.floor(math.log10(abs(value)))
    )
    # in words exactly when the data do not pin the sign
    assert tail == (stderr > abs(value))


@settings(max_examples=200, deadline=None)
@given(values, stderrs)
def test_fmt_pm_value_and_stderr_share_the_decimal_place(value, stderr):
    assume(stderr > 1e-8 * abs(value))
    text = fmt_pm(value, stderr)
    m = PM.match(text) or PM_EXP.match(text)
    v_txt, s_txt = m.group("v"), m.group("s")
    v_dec = len(v_txt.split(".")[1]) if "." in v_txt else 0
    s_dec = len(s_txt.split(".")[1]) if "." in s_txt else 0
    rounded_to_zero = float(v_txt) == 0 or v_dec > s_dec
    assert v_dec == s_dec or (rounded_to_zero and abs(value) < 10.0 ** (-s_dec))


def test_short_meaning_cuts_long_text_to_a_footnote():
    assert short_meaning("loading envelope slope") == ("loading envelope slope", "")
    doc = "flag point: unloading switches to y2 at v <= v_f (fitted by profile search)"
    assert short_meaning(doc) == ("flag point", doc)
    cell, note = short_meaning("word " * 20)
    assert len(cell) <= 40 and cell.endswith("…") and note == ("word " * 20).strip()
