"""The global search's certificate (issue 31 item 2): counted from the polished ends,
in FitResult, fit_report, fit.json's model record and the warnings; and the mid-loop
start state of both motors (item 4): the opening cycle and the two-level pre-history."""

from __future__ import annotations

import numpy as np
import pytest

import i2ris_calib.fitting.fit as F
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.pipeline import fit_kind, fit_warnings, search_starts
from i2ris_calib.hysteresis.presets import loading_trajectory, paper_like_params
from i2ris_calib.hysteresis.registry import model_for_kind
from i2ris_calib.io.fit import model_record
from i2ris_calib.model import Signals


@pytest.fixture(scope="module")
def egpi_case():
    rng = np.random.default_rng(7)
    _, v = loading_trajectory(rng, n_cycles=4, n_samples=1200)
    y = model_for_kind("egpi").with_values(paper_like_params("pitch+"))(v)
    return v, y + rng.normal(0.0, 0.05, v.size)


def test_certificate_counts_the_starts_that_reached_the_best(egpi_case):
    """at_best counts the polished or screened ends within 0.1 % of the final cost; the
    next minimum lies above it; every screened start is counted in ``starts``."""
    v, theta = egpi_case
    res = fit_kind("egpi", v, theta, FitConfig())
    cert = res.certificate
    assert cert is not None and cert.best_cost == pytest.approx(res.chisqr, rel=1e-12)
    assert 1 <= cert.at_best <= cert.starts + cert.hops
    assert cert.polished >= 1
    assert np.isnan(cert.next_cost) or cert.next_cost > cert.best_cost * (1 + F.SAME_MINIMUM)
    assert f"{cert.at_best} of {cert.starts + cert.hops} starts" in cert.text
    assert "global search" in res.fit_report()
    rec = model_record(res, "egpi", res.model, v)
    assert rec["certificate"]["at_best"] == cert.at_best
    assert rec["certificate"]["certified"] == (cert.at_best >= F.CERTIFIED_AT)


def test_a_lone_best_start_is_warned():
    """A certificate with one start at the best says so, in the warnings too."""
    cert = F.SearchCertificate(
        starts=5, polished=3, at_best=1, best_cost=1.0, next_cost=1.5, hops=2
    )
    assert not cert.certified and "only one start" in cert.warning
    assert "1.5x the best" in cert.text
    ok = F.SearchCertificate(
        starts=5, polished=3, at_best=2, best_cost=1.0, next_cost=float("nan"), hops=0
    )
    assert ok.warning is None and "next minimum" not in ok.text
    assert F.SearchCertificate.from_dict(cert.as_dict()) == cert


def test_certificate_warning_reaches_the_fit_warnings(egpi_case):
    v, theta = egpi_case
    res = fit_kind("gpi", v, theta, FitConfig())
    lone = F.SearchCertificate(8, 2, 1, res.chisqr, 2 * res.chisqr, 4)
    from dataclasses import replace

    assert any("only one start" in w for w in fit_warnings(replace(res, certificate=lone), v))


def test_search_starts_is_the_one_rule():
    """0 = by the data's size (8 up to 5,000 fitted samples, at least 2); a set value wins."""
    assert search_starts(0, 1000) == 8 and search_starts(0, 5000) == 8
    assert search_starts(0, 10_000) == 4 and search_starts(0, 50_000) == 2
    assert search_starts(3, 50_000) == 3


def test_opening_cycle_is_one_period_of_a_sine():
    t = np.arange(1000)
    v = np.round(1000 * np.sin(2 * np.pi * t / 100 + 0.3))
    k = F.opening_cycle(v)
    assert 99 <= k <= 101
    # replayed, the input continues into v[0] in the direction it left it
    assert v[k - 1] <= v[0] < v[1]
    assert F.opening_cycle(np.linspace(0, 1000, 500)) == 0  # never comes back


def test_two_level_prehistory_runs_through_both_turns():
    """The pre-history with an earlier turn: relaxed at v_turn, through v_from, into
    v[0], each ramp monotone; the replayed cycle follows it; without a turn it is the
    one ramp of before. (The fit's use of it: tests/fitting/test_optimum.py, e.g. agpi:2,
    a circle whose last turns lie beyond the recording's range.)"""
    v = np.array([100.0, 200.0, 300.0, 200.0, 100.0, 50.0, 100.0, 150.0])
    sig, n = F.prehistory_signals(Signals(v=v), v_from=-400.0, step=50.0, v_turn=900.0)
    pre = np.asarray(sig.v)[:n]
    assert pre[0] == 900.0 and np.isclose(pre.min(), -400.0)
    turn = int(np.argmin(pre))
    assert np.all(np.diff(pre[: turn + 1]) < 0) and np.all(np.diff(pre[turn:]) > 0)
    np.testing.assert_array_equal(np.asarray(sig.v)[n:], v)
    one, n1 = F.prehistory_signals(Signals(v=v), v_from=-400.0, step=50.0)
    assert np.asarray(one.v)[0] == -400.0 and np.all(np.diff(np.asarray(one.v)[:n1]) > 0)
    cyc, nc = F.prehistory_signals(Signals(v=v), v_from=-400.0, step=50.0, cycle=6)
    np.testing.assert_array_equal(np.asarray(cyc.v)[nc - 6 : nc], v[:6])


def test_other_motor_prehistory_runs_first_and_alone():
    """The other motor's levels: its ramps come first (this motor held where its own
    ramps begin), then this motor's ramps (the other held at its first value); the
    recording follows unchanged."""
    v = np.array([100.0, 200.0, 300.0, 250.0])
    vo = np.array([-50.0, 0.0, 50.0, 100.0])
    sig, n = F.prehistory_signals(
        Signals(v=v, v_other=vo), v_from=-200.0, step=100.0, other_levels=(700.0, -600.0),
        other_step=100.0,
    )  # fmt: skip
    pv, po = np.asarray(sig.v)[:n], np.asarray(sig.v_other)[:n]
    k = int(np.flatnonzero(np.diff(pv) != 0)[0]) + 1  # where this motor starts to move
    assert po[0] == 700.0 and np.isclose(po[:k].min(), -600.0)
    assert np.all(pv[:k] == -200.0) and np.all(po[k:] == vo[0])
    np.testing.assert_array_equal(np.asarray(sig.v)[n:], v)
    np.testing.assert_array_equal(np.asarray(sig.v_other)[n:], vo)
