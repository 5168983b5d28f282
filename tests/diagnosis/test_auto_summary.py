"""``--start auto``: the summary shows every path's alternatives, and the effects the
answer cannot rule out are the union over the paths (no model fits: result objects
built by hand)."""

from __future__ import annotations

from types import SimpleNamespace

from i2ris_calib.diagnosis.report import auto_summary, diagnosis_markdown
from i2ris_calib.diagnosis.results import Alternative, AutoDiagnosis


def _alt(effect, z, excluded=False, rms=0.3):
    return Alternative(effect, 0.1, z, 0.2, excluded, {"p": 1.0}, "", rms)


def _path(named, alternatives=(), not_excluded=()):
    steps = tuple(SimpleNamespace(effect=e, alternatives=tuple(alternatives)) for e in named)
    return SimpleNamespace(steps=steps, named_effects=list(named), not_excluded=tuple(not_excluded))


def _auto(gpi, egpi, start="gpi"):
    paths = {"gpi": gpi, "egpi": egpi}
    return AutoDiagnosis(start, paths[start], paths, False, 0.5, "")


def test_summary_shows_both_paths_alternatives():
    gpi = _path(["time_delay"], [_alt("rate_dependent_thresholds", 1.9)])
    egpi = _path(["time_delay"], [_alt("creep", 0.7)])
    text = auto_summary(_auto(gpi, egpi))
    assert text.startswith("time_delay; rate_dependent_thresholds not excluded, z = 1.9")
    assert "The egpi start: time_delay; creep not excluded, z = 0.7" in text
    # identical answers are not repeated
    same = auto_summary(_auto(gpi, gpi))
    assert same.endswith("The egpi start: the same.")
    assert same.count("rate_dependent_thresholds") == 1


def test_not_excluded_is_the_union_over_the_paths():
    gpi = _path([], not_excluded=[])
    egpi = _path([], not_excluded=[_alt("backlash", -1.2)])
    auto = _auto(gpi, egpi)
    assert [(k, a.effect) for k, a in auto.not_excluded] == [("egpi", "backlash")]
    assert "backlash not excluded" in auto_summary(auto)
    # an effect the answer names is not also listed as open from the other path
    named = _auto(_path(["backlash"]), egpi)
    assert named.not_excluded == ()
    # the answer's own entry comes first and is not duplicated
    both = _auto(_path([], not_excluded=[_alt("backlash", -0.5)]), egpi)
    assert [(k, a.z) for k, a in both.not_excluded] == [("gpi", -0.5)]
    # a path the held-out cycles exclude does not add what it left open
    excl = AutoDiagnosis("gpi", gpi, {"gpi": gpi, "egpi": egpi}, True, 4.6, "", True)
    assert excl.not_excluded == ()


def test_markdown_has_one_row_per_path():
    score = {"fit_rmse_deg": 0.1, "holdout_rmse_deg": 0.2, "bic": -1.0, "n_free": 8}
    rec = {
        "baseline": score,
        "final": score,
        "named_effects": [],
        "summary": "nothing missing",
        "start": "auto",
        "start_model": "egpi",
        "reconciliation": "both starts agree: nothing missing",
        "paths": {
            "gpi": {"named_effects": ["creep"], "summary": "creep; a | b", "baseline": score,
                    "final": score},
            "egpi": {"named_effects": [], "summary": "nothing missing", "baseline": score,
                     "final": score},
        },
        "figures": ["start.png"],
        "steps": [],
        "location_final": [],
        "last_candidates": [],
    }  # fmt: skip
    md = diagnosis_markdown(rec)
    assert "| gpi | creep | 0.2 -> 0.2 | creep; a / b |" in md
    assert "| egpi (answer) | nothing | 0.2 -> 0.2 | nothing missing |" in md
