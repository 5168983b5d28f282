"""Misuses of the public API (issue 19, "The Python API") are one-line CalibErrors that
name the function and the argument, raised before any work: never a numpy or Python
error from inside the library.

Every case here failed before the argument checks (a broadcast error, an IndexError in
``fit``, an AttributeError on a factory, a silently accepted NaN or column, ...).
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pandas as pd
import pytest

import i2ris_calib as ic
from i2ris_calib import (
    CalibError,
    DiagnosisConfig,
    FitConfig,
    PipelineConfig,
    SyncConfig,
    add_effect,
    compensate,
    continuous_egpi_model,
    diagnose,
    diagnose_from_starts,
    direction_datasets,
    egpi_model,
    fit,
    fit_model,
    gpi_model,
    i2ris_egpi_model,
    make_dataset,
    model_for_kind,
)
from i2ris_calib.hysteresis.presets import loading_trajectory, paper_like_params

N = 600


@pytest.fixture(scope="module")
def arrays():
    rng = np.random.default_rng(19)
    t, v = loading_trajectory(rng, n_cycles=3, n_samples=N)
    truth = i2ris_egpi_model(**paper_like_params("yaw+"))
    theta = truth(v) + rng.normal(0.0, 0.1, v.size)
    return t, v, theta, truth


@pytest.fixture(scope="module")
def data(arrays):
    t, v, theta, _ = arrays
    return make_dataset("yaw", "+", t, v, theta)


def _nan_at(x: np.ndarray, k: int) -> np.ndarray:
    y = np.array(x, dtype=float)
    y[k] = np.nan
    return y


def _frame(t, v, theta) -> pd.DataFrame:
    return pd.DataFrame({"time_s": t, "enc_yaw": v, "yaw_deg": theta})


def check(call, *patterns: str) -> None:
    """``call()`` raises a one-line CalibError whose message contains every pattern
    (regular expressions: the function's and the argument's names, the fix)."""
    with pytest.raises(CalibError) as exc:
        call()
    msg = str(exc.value)
    assert "\n" not in msg, msg
    for p in patterns:
        assert re.search(p, msg), f"{p!r} not in {msg!r}"


# --------------------------------------------------------------------------- data layer

MAKE_DATASET = {
    "nan_input": (
        lambda t, v, th: make_dataset("yaw", "+", t, _nan_at(v, 12), th),
        [r"^make_dataset: enc has 1 NaN value \(first at index 12\)", "angles may be NaN"],
    ),
    "nan_time": (
        lambda t, v, th: make_dataset("yaw", "+", _nan_at(t, 3), v, th),
        ["make_dataset: time_s has 1 NaN", "index 3"],
    ),
    "different_lengths": (
        lambda t, v, th: make_dataset("yaw", "+", t, v, th[:-20]),
        [f"make_dataset: theta_deg has {N - 20} samples but enc {N}", "same length"],
    ),
    "time_shorter": (
        lambda t, v, th: make_dataset("yaw", "+", t[:-2], v, th),
        [f"time_s has {N - 2} samples but enc {N}"],
    ),
    "column_arrays": (
        lambda t, v, th: make_dataset("yaw", "+", t, v[:, None], th),
        [rf"make_dataset: enc has shape \({N}, 1\)", r"\.ravel\(\)"],
    ),
    "none_input": (
        lambda t, v, th: make_dataset("yaw", "+", t, None, th),
        ["make_dataset: enc is None"],
    ),
    "str_input": (
        lambda t, v, th: make_dataset("yaw", "+", t, "enc_yaw", th),
        ["make_dataset: enc is the str 'enc_yaw'"],
    ),
    "dataframe_as_array": (
        lambda t, v, th: make_dataset("yaw", "+", _frame(t, v, th), v, th),
        ["make_dataset: time_s is a pandas DataFrame", r"df\['time_s'\]"],
    ),
    "decreasing_time": (
        lambda t, v, th: make_dataset("yaw", "+", t[::-1], v, th),
        ["make_dataset: time_s decreases at index 1", "time order"],
    ),
    "unknown_axis": (
        lambda t, v, th: make_dataset("roll", "+", t, v, th),
        ["make_dataset: axis 'roll' is not one of 'yaw', 'pitch'"],
    ),
    "unknown_direction": (
        lambda t, v, th: make_dataset("yaw", "up", t, v, th),
        ["make_dataset: direction 'up' is not one of"],
    ),
    "holdout_fraction": (
        lambda t, v, th: make_dataset("yaw", "+", t, v, th, holdout_fraction=1.5),
        ["make_dataset: holdout_fraction = 1.5", "< 1"],
    ),
    "bands_not_bands": (
        lambda t, v, th: make_dataset("yaw", "+", t, v, th, bands=3.0),
        ["make_dataset: bands is a float", "give a Bands"],
    ),
    "other_axis_length": (
        lambda t, v, th: make_dataset("yaw", "+", t, v, th, enc_other=v[:-3]),
        [f"make_dataset: enc_other has {N - 3} samples but enc {N}"],
    ),
    "infinite_angle": (
        lambda t, v, th: make_dataset("yaw", "+", t, v, np.where(np.arange(N) == 7, np.inf, th)),
        ["make_dataset: theta_deg has 1 infinite value", "NaN"],
    ),
}


@pytest.mark.parametrize("case", MAKE_DATASET)
def test_make_dataset_misuse(arrays, case):
    t, v, theta, _ = arrays
    call, patterns = MAKE_DATASET[case]
    check(lambda: call(t, v, theta), *patterns)


DIRECTION_DATASETS = {
    "nan_input": (
        lambda t, v, th: direction_datasets("yaw", t, _nan_at(v, 5), th),
        ["direction_datasets: enc has 1 NaN value"],
    ),
    "different_lengths": (
        lambda t, v, th: direction_datasets("yaw", t, v, th[:-4]),
        [f"direction_datasets: theta_deg has {N - 4} samples but enc {N}"],
    ),
    "column_arrays": (
        lambda t, v, th: direction_datasets("yaw", t[:, None], v, th),
        [r"direction_datasets: time_s has shape", r"\.ravel\(\)"],
    ),
    "min_samples": (
        lambda t, v, th: direction_datasets("yaw", t, v, th, min_samples="50"),
        ["direction_datasets: min_samples is the str '50'"],
    ),
    "unknown_direction": (
        lambda t, v, th: direction_datasets("yaw", t, v, th, directions=("up",)),
        [r"direction_datasets: directions\[0\] 'up' is not one of"],
    ),
}


@pytest.mark.parametrize("case", DIRECTION_DATASETS)
def test_direction_datasets_misuse(arrays, case):
    t, v, theta, _ = arrays
    call, patterns = DIRECTION_DATASETS[case]
    check(lambda: call(t, v, theta), *patterns)


def test_legitimate_data_is_still_accepted(arrays):
    """NaN angles (unmeasured), pandas columns, lists, a path as source, a direction
    given as a str: all fine (these passed before too)."""
    t, v, theta, _ = arrays
    df = _frame(t, v, _nan_at(theta, 10))
    ds = make_dataset("yaw", "+", df["time_s"], df["enc_yaw"], df["yaw_deg"])
    assert ds.rows["angle_missing"] == 1 and np.isnan(ds.theta_deg[10])
    assert make_dataset("yaw", "+", list(t), list(v), list(theta)).n_samples == N
    from pathlib import Path

    assert make_dataset("yaw", "+", t, v, theta, source=Path("s.csv")).source == "s.csv"
    assert [d.name for d in direction_datasets("yaw", t, v, theta, directions="+")] == ["yaw+"]


# --------------------------------------------------------------------------- models


MODELS = {
    "gpi_n_zero": (lambda: gpi_model(n=0), ["gpi_model: n = 0 is out of range", ">= 1"]),
    "gpi_n_str": (lambda: gpi_model(n="30"), ["gpi_model: n is the str '30'; give an integer"]),
    "gpi_unknown_name": (
        lambda: gpi_model(kappa=3.0),
        ["gpi_model: unknown parameter 'kappa' for model 'gpi'", "valid: a1"],
    ),
    "gpi_value_str": (lambda: gpi_model(a1="x"), ["gpi_model: a1 is the str 'x'"]),
    "gpi_value_nan": (lambda: gpi_model(a1=math.nan), ["gpi_model: a1 is nan", "finite"]),
    "egpi_deadband_str": (
        lambda: i2ris_egpi_model(deadband_counts="2"),
        ["i2ris_egpi_model: deadband_counts is the str '2'"],
    ),
    "egpi_close_name": (
        lambda: i2ris_egpi_model(kapa=3.0),
        ["i2ris_egpi_model: unknown parameter 'kapa'", "did you mean 'kappa'"],
    ),
    "egpi_c_unknown_name": (
        lambda: continuous_egpi_model(aa=1.0),
        ["continuous_egpi_model: unknown parameter 'aa'"],
    ),
    "general_missing_values": (
        lambda: egpi_model([("linear", "linear")], {}),
        ["egpi_model: values missing", "l1_slope"],
    ),
    "general_bad_envelope": (
        lambda: egpi_model([("lin", "linear")], {}),
        [r"egpi_model: envelopes\[0\] kind_l 'lin'", "did you mean 'linear'"],
    ),
    "general_no_arguments": (
        lambda: egpi_model(),
        ["egpi_model: envelopes and values not given", "call i2ris_egpi_model()"],
    ),
    "general_no_values": (
        lambda: egpi_model([("linear", "linear")]),
        ["egpi_model: values not given", "i2ris_egpi_model()"],
    ),
    "general_envelopes_str": (
        lambda: egpi_model("linear", {}),
        ["egpi_model: envelopes is the str 'linear'"],
    ),
    "kind_n_str": (lambda: model_for_kind("egpi", n="x"), ["model_for_kind: n is the str 'x'"]),
    "kind_value_nan": (
        lambda: model_for_kind("gpi", a1=math.nan),
        ["model_for_kind: a1 is nan"],
    ),
    "kind_not_str": (
        lambda: model_for_kind(gpi_model()),
        ["model_for_kind: kind is a GPIModel", "gpi, egpi, egpi_c"],
    ),
}


@pytest.mark.parametrize("case", MODELS)
def test_model_factory_misuse(case):
    call, patterns = MODELS[case]
    check(call, *patterns)


MODEL_CALLS = {
    "nan_input": (lambda m, v, th: m(_nan_at(v, 12)), ["egpi model: signals has 1 NaN value"]),
    "column_input": (lambda m, v, th: m(v[:, None]), [r"egpi model: signals has shape \("]),
    "none_input": (lambda m, v, th: m(None), ["egpi model: signals is None"]),
    "dataframe_input": (
        lambda m, v, th: m(_frame(v, v, th)),
        ["egpi model: signals is a pandas DataFrame"],
    ),
    "guess_lengths": (
        lambda m, v, th: m.guess(v, th[:-3]),
        [f"egpi.guess: theta_deg has {N - 3} samples but v {N}"],
    ),
    "guess_nan_input": (lambda m, v, th: m.guess(_nan_at(v, 4), th), ["egpi.guess: v has 1 NaN"]),
    "effect_model_nan_input": (
        lambda m, v, th: add_effect(m, "time_delay")(_nan_at(v, 2)),
        ["egpi\\+time_delay model: signals has 1 NaN"],
    ),
}


@pytest.mark.parametrize("case", MODEL_CALLS)
def test_model_call_misuse(arrays, case):
    _, v, theta, truth = arrays
    call, patterns = MODEL_CALLS[case]
    check(lambda: call(truth, v, theta), *patterns)


# --------------------------------------------------------------------------- fit

FIT = {
    "uncalled_factory": (
        lambda d, v, th: fit(i2ris_egpi_model, d),
        [
            r"^fit: model is the factory i2ris_egpi_model, not a model; "
            r"call it: i2ris_egpi_model\(\)$"
        ],
    ),
    "model_none": (lambda d, v, th: fit(None, d), ["fit: model is None"]),
    "model_str": (
        lambda d, v, th: fit("egpi", d),
        ["fit: model is the str 'egpi'", r"model_for_kind\('egpi'\)"],
    ),
    "arguments_swapped": (
        lambda d, v, th: fit(d, i2ris_egpi_model()),
        ["fit: model is a Dataset", r"fit\(model, data\)"],
    ),
    "fit_result_as_model": (
        lambda d, v, th: fit(_FakeResult(i2ris_egpi_model()), d),
        ["fit: model is a _FakeResult", r"model\.model"],
    ),
    "config_str": (
        lambda d, v, th: fit(i2ris_egpi_model(), d, "trf"),
        ["fit: config is the str 'trf'; give a FitConfig"],
    ),
    "config_dataframe": (
        lambda d, v, th: fit(i2ris_egpi_model(), d, _frame(v, v, th)),
        ["fit: config is a pandas DataFrame"],
    ),
    "config_class": (
        lambda d, v, th: fit(i2ris_egpi_model(), d, FitConfig),
        [r"fit: config is the class FitConfig, not a FitConfig; call it: FitConfig\(\)"],
    ),
    "config_pipeline": (
        lambda d, v, th: fit(i2ris_egpi_model(), d, PipelineConfig()),
        [r"fit: config is a PipelineConfig; give its FitConfig section: config\.fit"],
    ),
    "data_dataframe": (
        lambda d, v, th: fit(i2ris_egpi_model(), _frame(v, v, th)),
        ["fit: data is a pandas DataFrame", "make_dataset"],
    ),
    "data_none": (lambda d, v, th: fit(i2ris_egpi_model(), None), ["fit: data is None"]),
    "data_list_of_datasets": (
        lambda d, v, th: fit(i2ris_egpi_model(), [d, d]),
        [r"fit: data is a list of 2 datasets \(yaw\+, yaw\+\); give one, e.g. data\[0\]"],
    ),
    "pair_nan_input": (
        lambda d, v, th: fit(i2ris_egpi_model(), (_nan_at(v, 12), th)),
        [r"fit: data\[0\] \(the input v\) has 1 NaN value \(first at index 12\)"],
    ),
    "pair_lengths": (
        lambda d, v, th: fit(i2ris_egpi_model(), (v, th[:-3])),
        [rf"fit: data\[1\] \(theta_deg\) has {N - 3} samples but data\[0\]"],
    ),
    "pair_columns": (
        lambda d, v, th: fit(i2ris_egpi_model(), (v[:, None], th[:, None])),
        [r"fit: data\[0\] \(the input v\) has shape", r"\.ravel\(\)"],
    ),
    "triple": (
        lambda d, v, th: fit(i2ris_egpi_model(), (v, v, th)),
        ["fit: data is a tuple of 3 items", r"\(v, theta_deg\)"],
    ),
    "holdout_length": (
        lambda d, v, th: fit(i2ris_egpi_model(), (v, th), holdout=np.zeros(3, bool)),
        ["fit: holdout has 3 samples but the data 600"],
    ),
    "holdout_indices": (
        lambda d, v, th: fit(i2ris_egpi_model(), (v, th), holdout=np.arange(N) % 7),
        ["fit: holdout is not a boolean mask", "index array"],
    ),
    "holdout_with_dataset": (
        lambda d, v, th: fit(i2ris_egpi_model(), d, holdout=np.zeros(N, bool)),
        ["fit: holdout is for", "data.holdout|replace"],
    ),
    "dataset_edited_to_column": (
        lambda d, v, th: fit(
            i2ris_egpi_model(), dataclasses.replace(d, theta_deg=d.theta_deg[:, None])
        ),
        [r"fit: data\.theta_deg has shape"],
    ),
}


@dataclasses.dataclass
class _FakeResult:
    """Stands for a FitResult (anything carrying a fitted ``.model``)."""

    model: object


@pytest.mark.parametrize("case", FIT)
def test_fit_misuse(arrays, data, case):
    _, v, theta, _ = arrays
    call, patterns = FIT[case]
    check(lambda: call(data, v, theta), *patterns)


FIT_MODEL = {
    "uncalled_factory": (
        lambda v, th: fit_model(gpi_model, v, th),
        [r"fit_model: model is the factory gpi_model, not a model; call it: gpi_model\(\)"],
    ),
    "column_input": (
        lambda v, th: fit_model(gpi_model(), v[:, None], th),
        [r"fit_model: signals has shape", r"\.ravel\(\)"],
    ),
    "fit_mask_length": (
        lambda v, th: fit_model(gpi_model(), v, th, fit_mask=np.ones(5, bool)),
        ["fit_model: fit_mask has 5 samples"],
    ),
    "start_size": (
        lambda v, th: fit_model(gpi_model(), v, th, starts=[np.zeros(3)]),
        [r"fit_model: starts\[0\] has 3 values; give 8"],
    ),
    "start_not_a_list": (
        lambda v, th: fit_model(gpi_model(), v, th, starts=gpi_model().values),
        [r"fit_model: starts is one vector; give a list of start vectors, e.g. \[x0\]"],
    ),
    "unknown_method": (
        lambda v, th: fit_model(gpi_model(), v, th, method="levenberg"),
        ["fit_model: method 'levenberg' is not one of 'lm', 'trf'"],
    ),
}


@pytest.mark.parametrize("case", FIT_MODEL)
def test_fit_model_misuse(arrays, case):
    _, v, theta, _ = arrays
    call, patterns = FIT_MODEL[case]
    check(lambda: call(v, theta), *patterns)


def test_fit_accepts_none_as_the_default_config(arrays):
    """``config=None`` means the defaults, as in ``diagnose`` and ``load_synced``."""
    _, v, theta, _ = arrays
    res = fit(gpi_model(), (v, theta), None)
    assert res.converged


# --------------------------------------------------------------------------- diagnosis

DIAGNOSE = {
    "uncalled_factory": (
        lambda d, m: diagnose(i2ris_egpi_model, d),
        [r"diagnose: start is the factory i2ris_egpi_model, not a model"],
    ),
    "data_pair": (
        lambda d, m: diagnose(m, (d.v, d.theta_deg)),
        ["diagnose: data is a tuple of 2 items", "give a Dataset"],
    ),
    "data_list": (
        lambda d, m: diagnose(m, [d]),
        [r"diagnose: data is a list of 1 dataset \(yaw\+\); give one, e.g. data\[0\]"],
    ),
    "config_str": (
        lambda d, m: diagnose(m, d, "fast"),
        ["diagnose: config is the str 'fast'; give a DiagnosisConfig"],
    ),
    "config_fit_config": (
        lambda d, m: diagnose(m, d, FitConfig()),
        ["diagnose: config is a FitConfig; give a DiagnosisConfig"],
    ),
    "progress_not_callable": (
        lambda d, m: diagnose(m, d, progress="bar"),
        ["diagnose: progress is the str 'bar'; give a function or None"],
    ),
    "auto_data_none": (
        lambda d, m: diagnose_from_starts(None),
        ["diagnose_from_starts: data is None; give a Dataset"],
    ),
    "auto_config_str": (
        lambda d, m: diagnose_from_starts(d, "x"),
        ["diagnose_from_starts: config is the str 'x'"],
    ),
    "auto_fit_config_str": (
        lambda d, m: diagnose_from_starts(d, None, "trf"),
        ["diagnose_from_starts: fit_config is the str 'trf'; give a FitConfig"],
    ),
    "auto_starts_str": (
        lambda d, m: diagnose_from_starts(d, starts="gpi"),
        [r"diagnose_from_starts: starts is the str 'gpi'; give a tuple"],
    ),
    "effect_on_factory": (
        lambda d, m: add_effect(i2ris_egpi_model, "time_delay"),
        [r"add_effect: model is the factory i2ris_egpi_model, not a model"],
    ),
    "effect_on_none": (
        lambda d, m: add_effect(None, "time_delay"),
        ["add_effect: model is None"],
    ),
    "effect_name_none": (
        lambda d, m: add_effect(m, None),
        ["add_effect: name is None; give an effect name", "time_delay"],
    ),
    "effect_values_list": (
        lambda d, m: add_effect(m, "time_delay", [0.1]),
        ["add_effect: values is a list", r"\{'tau_s'"],
    ),
    "effect_value_str": (
        lambda d, m: add_effect(m, "time_delay", {"tau_s": "0.1"}),
        [r"add_effect: values\['tau_s'\] is the str '0.1'; give a number"],
    ),
}


@pytest.mark.parametrize("case", DIAGNOSE)
def test_diagnosis_misuse(arrays, data, case):
    call, patterns = DIAGNOSE[case]
    check(lambda: call(data, arrays[3]), *patterns)


# --------------------------------------------------------------------------- compensate

LIMITS = (0.0, 6000.0)
COMPENSATE = {
    "uncalled_factory": (
        lambda m, t, th: compensate(i2ris_egpi_model, th, v_limits=LIMITS),
        [r"compensate: model is the factory i2ris_egpi_model, not a model"],
    ),
    "column_target": (
        lambda m, t, th: compensate(m, th[:, None], v_limits=LIMITS),
        [r"compensate: target_deg has shape", r"\.ravel\(\)"],
    ),
    "none_target": (
        lambda m, t, th: compensate(m, None, v_limits=LIMITS),
        ["compensate: target_deg is None"],
    ),
    "dataframe_target": (
        lambda m, t, th: compensate(m, _frame(t, t, th), v_limits=LIMITS),
        ["compensate: target_deg is a pandas DataFrame", "one column"],
    ),
    "times_length": (
        lambda m, t, th: compensate(m, th, t[:-1], v_limits=LIMITS),
        [f"compensate: t_s has {N - 1} samples but target_deg {N}"],
    ),
    "limits_scalar": (
        lambda m, t, th: compensate(m, th, v_limits=6000),
        [r"compensate: v_limits is an int \(6000\); give \(lo, hi\)"],
    ),
    "limits_none": (
        lambda m, t, th: compensate(m, th, v_limits=None),
        [r"compensate: v_limits is None; give \(lo, hi\)"],
    ),
    "quantum_str": (
        lambda m, t, th: compensate(m, th, v_limits=LIMITS, quantum="1"),
        ["compensate: quantum is the str '1'; give a number"],
    ),
    "rate_str": (
        lambda m, t, th: compensate(m, th, t, v_limits=LIMITS, max_rate="500"),
        ["compensate: max_rate is the str '500'; give a number"],
    ),
}


@pytest.mark.parametrize("case", COMPENSATE)
def test_compensate_misuse(arrays, case):
    t, _, theta, truth = arrays
    target = np.clip(theta, 1.0, 30.0)
    call, patterns = COMPENSATE[case]
    check(lambda: call(truth, t, target), *patterns)


# --------------------------------------------------------------------------- files

FILES = {
    "synced_path_none": (
        lambda df: ic.load_synced(None, "yaw"),
        ["load_synced: path is None; give the path of a synced CSV"],
    ),
    "synced_path_dataframe": (
        lambda df: ic.load_synced(df, "yaw"),
        ["load_synced: path is a pandas DataFrame", "make_dataset"],
    ),
    "synced_paths_list": (
        lambda df: ic.load_synced(["a.csv", "b.csv"], "yaw"),
        ["load_synced: path is a list of 2 items"],
    ),
    "synced_axis": (
        lambda df: ic.load_synced("missing.csv", "roll"),
        ["load_synced: axis 'roll' is not one of 'yaw', 'pitch'"],
    ),
    "synced_config_str": (
        lambda df: ic.load_synced("missing.csv", "yaw", "trf"),
        ["load_synced: config is the str 'trf'; give a FitConfig"],
    ),
    "config_path_dataframe": (
        lambda df: ic.load_config(df),
        ["load_config: path is a pandas DataFrame", "give the path of a TOML"],
    ),
    "config_path_int": (
        lambda df: ic.load_config(3),
        [r"load_config: path is an int \(3\)"],
    ),
}


@pytest.mark.parametrize("case", FILES)
def test_file_loader_misuse(arrays, case):
    t, v, theta, _ = arrays
    call, patterns = FILES[case]
    check(lambda: call(_frame(t, v, theta)), *patterns)


# --------------------------------------------------------------------------- configs

CONFIGS = {
    "int_field_str": (lambda: FitConfig(n_starts="3"), ["FitConfig: n_starts is the str '3'"]),
    "int_field_none": (lambda: FitConfig(seed=None), ["FitConfig: seed is None; give an integer"]),
    "int_field_float": (
        lambda: FitConfig(n_operators=30.0),
        [r"FitConfig: n_operators is a float \(30.0\); give an integer"],
    ),
    "float_field_nan": (lambda: FitConfig(f_scale_deg=math.nan), ["FitConfig: f_scale_deg is NaN"]),
    "tuple_field_str": (
        lambda: FitConfig(fixed_egpi="lam"),
        [r"FitConfig: fixed_egpi is the str 'lam'; give a tuple, e.g. \('lam',\)"],
    ),
    "bool_field_str": (
        lambda: FitConfig(signed="yes"),
        ["FitConfig: signed is the str 'yes'; give True or False"],
    ),
    "bad_value": (lambda: FitConfig(method="levenberg"), ["method 'levenberg' is not one of"]),
    "float_field_str": (
        lambda: DiagnosisConfig(alpha="0.05"),
        ["DiagnosisConfig: alpha is the str '0.05'; give a number"],
    ),
    "literal_field": (
        lambda: SyncConfig(method="flash"),
        ["SyncConfig: method is 'flash', not one of 'auto', 'event'"],
    ),
    "section_str": (
        lambda: PipelineConfig(fit="trf"),
        ["PipelineConfig: fit is the str 'trf'; give a FitConfig"],
    ),
    "section_class": (
        lambda: PipelineConfig(fit=FitConfig),
        [r"PipelineConfig: fit is the class FitConfig, not a FitConfig; call it: FitConfig\(\)"],
    ),
}


@pytest.mark.parametrize("case", CONFIGS)
def test_config_misuse(case):
    call, patterns = CONFIGS[case]
    check(call, *patterns)


def test_configs_still_accept_numbers_of_any_kind():
    """An int for a float setting, numpy scalars, a list for a tuple: fine."""
    cfg = FitConfig(deadband_counts=2, f_scale_deg=np.float32(0.5), n_starts=np.int64(3))
    assert cfg.n_starts == 3
    assert FitConfig(fixed_egpi=["lam", "kappa"]).fixed_egpi == ["lam", "kappa"]
    assert PipelineConfig(fit=cfg).fit is cfg
