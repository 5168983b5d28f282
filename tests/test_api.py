"""The Python API a notebook user writes: top-level imports, fit(model, data), FitResult."""

from __future__ import annotations

import doctest
import importlib
import re
from pathlib import Path

import numpy as np
import pytest

import i2ris_calib
from i2ris_calib import (
    CalibError,
    FitConfig,
    FitResult,
    fit,
    gpi_model,
    i2ris_egpi_model,
    make_dataset,
)
from i2ris_calib.hysteresis.presets import loading_trajectory, paper_like_params

SIGMA = 0.1
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(11)
    t, v = loading_trajectory(rng, n_cycles=4, n_samples=2500)
    y = i2ris_egpi_model(deadband_counts=2.0).evaluate_dict(v, paper_like_params("yaw+"))
    return make_dataset("yaw", "+", t, v, y + rng.normal(0, SIGMA, v.size))


def test_every_documented_name_imports():
    for name in i2ris_calib.__all__:
        assert getattr(i2ris_calib, name) is not None, name
    with pytest.raises(AttributeError):
        i2ris_calib.no_such_name  # noqa: B018
    assert issubclass(CalibError, ValueError)


def test_fit_of_a_default_model_reaches_the_noise(data):
    """`fit(i2ris_egpi_model(), data)`: data-driven starts by default (issue: 0.359 deg).
    The kind's own path, as the command line: the truth's v' dead band (2 counts) is
    given as ``[fit] deadband_counts`` (default: derived from the data)."""
    res = fit(i2ris_egpi_model(), data, FitConfig(deadband_counts=2.0))
    assert isinstance(res, FitResult) and res.converged
    # tolerance from the noise: held-out RMSE within 10 % of sigma
    assert res.holdout_metrics.rmse_deg <= 1.1 * SIGMA
    # reduced chi-square estimates the noise variance (n ~ 1800: within 10 %)
    assert res.redchi == pytest.approx(SIGMA**2, rel=0.1)
    assert fit(gpi_model(), data).holdout_metrics.rmse_deg > 2 * res.holdout_metrics.rmse_deg


def test_fit_result_reports(data):
    res = fit(i2ris_egpi_model(), data)
    r = repr(res)
    assert len(r) < 200 and "egpi" in r and "converged" in r
    rep = res.fit_report()
    for name in res.free:
        assert f"\n    {name} " in rep
    # the held-out RMSE has its unit; v_f is profiled (no stderr by design), said so,
    # and not counted with the least-squares parameters (as the report counts them)
    assert re.search(r"held-out [0-9.]+ deg,", r), r
    assert res.profiled == ("v_f",) and res.n_fitted == len(res.free) - 1
    assert f"{res.n_fitted} free (+1 profiled)" in r
    assert f"free parameters = {res.n_fitted} (+ v_f profiled)" in rep
    assert "nan" not in rep and re.search(r"\n    v_f +=.*\(profiled\)", rep)
    # why the optimiser stopped, in plain words (not scipy's "`ftol` termination ...")
    assert "termination" not in rep and "`" not in res.message
    assert "<table>" in res._repr_html_()
    for (a, b), c in res.correlations.items():
        assert a in res.free and b in res.free and -1.0 - 1e-9 <= c <= 1.0 + 1e-9
    assert all(
        n.code in {"left_bounds", "refit_from_start", "not_a_minimum", "at_bound"}
        for n in res.notes
    )


def test_guess_gives_the_data_driven_start(data):
    m = i2ris_egpi_model()
    g = m.guess(data.v, data.theta_deg)
    assert g is not m and m.value_dict() == i2ris_egpi_model().value_dict()  # not mutated

    # the start is closer to the data than the factory defaults (a start, not a fit)
    def rms(model):
        return float(np.sqrt(np.nanmean((model(data.signals) - data.theta_deg) ** 2)))

    assert rms(g) < rms(m)


def test_docs_api_examples_run():
    """docs/api.md's examples run as doctests."""
    failures, tests = doctest.testfile(
        str(ROOT / "docs" / "api.md"), module_relative=False, optionflags=doctest.ELLIPSIS
    )
    assert tests > 0 and failures == 0


_HOMES = ("hysteresis.kernel", "hysteresis.models", "hysteresis.paper", "fitting.fit")
_HOMES += ("fitting.metrics", "fitting.pipeline")


def _resolve(name: str):
    """The object a table entry like ``kernel.thresholds`` or ``GPIModel.evaluate`` names."""
    parts = name.split(".")
    for i in range(len(parts) - 1, 0, -1):  # a module path given in full or from its package
        for mod in (".".join(parts[:i]), f"hysteresis.{'.'.join(parts[:i])}"):
            try:
                obj = importlib.import_module(f"i2ris_calib.{mod}")
            except ModuleNotFoundError:
                continue
            for attr in parts[i:]:
                obj = getattr(obj, attr)
            return obj
    for mod in _HOMES:  # a bare name: in one of the modules of the equations
        obj = importlib.import_module(f"i2ris_calib.{mod}")
        if hasattr(obj, parts[0]):
            for attr in parts:
                obj = getattr(obj, attr)
            return obj
    raise AttributeError(name)


@pytest.mark.parametrize("doc", ["api.md", "models.md"])
def test_equation_table_names_exist(doc):
    """Every function and test named in the Eq -> code -> test table exists."""
    text = (ROOT / "docs" / doc).read_text()
    rows = text[text.index("| Eq | what | code | test |") :].split("\n\n")[0].splitlines()[2:]
    assert len(rows) >= 14
    sources = "".join(f.read_text() for f in (ROOT / "tests").rglob("test_*.py"))
    for row in rows:
        _, _, code, tests = (c.strip() for c in row.strip().strip("|").split(" | "))
        for name in re.findall(r"`([A-Za-z_][\w.]*)`", code):
            assert _resolve(name) is not None
        names = re.findall(r"::(\w+)`", tests)
        assert names, row
        for test in names:
            assert f"def {test}(" in sources, f"{doc}: test {test} not found"


def test_effects_and_diagnosis_are_public(data):
    """`add_effect` builds a callable extended model; a time delay shifts the angle by
    exactly tau on a uniformly sampled record (tau a whole number of samples)."""
    from i2ris_calib import CATALOGUE, DiagnosisConfig, add_effect, diagnose, diagnose_from_starts

    assert callable(diagnose) and callable(diagnose_from_starts)
    assert "time_delay" in CATALOGUE and DiagnosisConfig().alpha > 0
    dt = float(np.median(np.diff(data.signals.t_s)))
    base = i2ris_egpi_model(**paper_like_params("yaw+"))
    delayed = add_effect(base, "time_delay", {"tau_s": 10 * dt})
    y, yd = base(data.signals), delayed(data.signals)
    assert delayed.names[: len(base.names)] == base.names
    np.testing.assert_allclose(yd[100:], y[90:-10], atol=1e-9)


# ---------------------------------------------------------------- the API is visible

_STUB = ROOT / "src" / "i2ris_calib" / "__init__.pyi"


def _stub_names() -> tuple[dict[str, str], set[str], list[str], dict[str, list[str]]]:
    """The stub's ``{name: module}`` imports, ``__version__``-like annotated names,
    ``__all__`` and ``{function: parameter names}`` of the functions it defines."""
    import ast

    tree = ast.parse(_STUB.read_text())
    imported, annotated, defs, all_ = {}, set(), {}, []
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module.startswith("i2ris_calib"):
            for a in node.names:
                assert a.asname == a.name, f"{a.name}: re-export as `{a.name} as {a.name}`"
                imported[a.name] = node.module
        elif isinstance(node, ast.AnnAssign):
            annotated.add(node.target.id)
        elif isinstance(node, ast.FunctionDef):
            defs[node.name] = [a.arg for a in (*node.args.args, *node.args.kwonlyargs)]
        elif isinstance(node, ast.Assign) and node.targets[0].id == "__all__":
            all_ = ast.literal_eval(node.value)
    return imported, annotated, all_, defs


def test_stub_and_all_agree():
    """__init__.pyi declares exactly ``__all__``, each name from the module that
    ``__getattr__`` loads it from."""
    imported, annotated, stub_all, defs = _stub_names()
    assert stub_all == list(i2ris_calib.__all__)
    assert {*imported, *annotated, *defs} == set(i2ris_calib.__all__)
    assert imported == i2ris_calib._API
    assert set(defs) == set(i2ris_calib._IO)


def test_dir_lists_the_public_names():
    import subprocess
    import sys

    # in a fresh interpreter: before any name was loaded
    out = subprocess.run(
        [sys.executable, "-c", "import i2ris_calib; print(' '.join(dir(i2ris_calib)))"],
        capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    # exactly the stub's names: no private helper of the face (its _API, _load, ...)
    _, _, stub_all, _ = _stub_names()
    assert out == sorted(stub_all) == dir(i2ris_calib)
    assert "_API" not in out and "__version__" in out


def test_public_signatures_are_the_real_ones():
    """No public callable reads ``(*args, **kwargs)``: a wrapper shows what it wraps,
    and the two functions defined in the package face take the stub's parameters."""
    import inspect

    _, _, _, defs = _stub_names()
    for name in i2ris_calib.__all__:
        obj = getattr(i2ris_calib, name)
        if not inspect.isfunction(obj):
            continue
        kinds = {p.kind for p in inspect.signature(obj).parameters.values()}
        assert kinds - {inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD}, name
        if name in defs:
            assert list(inspect.signature(obj).parameters) == defs[name], name
    sig = inspect.signature(i2ris_calib.fit_model)
    assert list(sig.parameters)[:3] == ["model", "signals", "theta_deg"]
    assert "fit_model" in i2ris_calib.fit_model.__name__ and "Eq24" in i2ris_calib.fit_model.__doc__


def test_a_loaded_name_is_one_object():
    assert i2ris_calib.load_synced is i2ris_calib.load_synced
    assert i2ris_calib.fit is importlib.import_module("i2ris_calib.fitting.pipeline").fit


def test_import_stays_cheap():
    """``import i2ris_calib`` (and so the CLI's ``--help``) loads none of the heavy
    modules: they come with the first public name that needs them."""
    import subprocess
    import sys

    code = (
        "import sys, i2ris_calib; "
        "print(' '.join(m for m in ('numba', 'scipy', 'cv2', 'matplotlib', 'pandas') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == []


def test_help_of_fit_and_load_synced_reads_well():
    """help(fit) shows no whole FitConfig(...) repr as a default; help(load_synced)
    says what it returns."""
    import inspect
    import pydoc

    assert inspect.signature(fit).parameters["config"].default is None
    assert "FitConfig(method" not in pydoc.render_doc(fit, renderer=pydoc.plaintext)
    doc = i2ris_calib.load_synced.__doc__
    assert "a list of ``Dataset``" in doc and "``[0]`` is" in doc
