from dataclasses import dataclass, field
from typing import Literal

import pytest

from i2ris_calib.config import PipelineConfig
from i2ris_calib.errors import CalibError
from i2ris_calib.io.config_io import dataclass_from_mapping, load_config


@dataclass(frozen=True)
class Inner:
    sigma_deg: float = 0.1
    n: int = 3


@dataclass(frozen=True)
class Outer:
    mode: Literal["gpi", "egpi"] = "egpi"
    inner: Inner = field(default_factory=Inner)
    names: tuple[str, ...] = ()

    def validate(self):
        if "bad" in self.names:
            raise ValueError("names must not contain 'bad'")


def test_unknown_key_suggests_closest():
    with pytest.raises(CalibError, match="unknown key 'sigma_dg'.*did you mean 'sigma_deg'"):
        dataclass_from_mapping(Outer, {"inner": {"sigma_dg": 1.0}}, where="c.toml")


def test_types_are_checked_and_coerced():
    obj = dataclass_from_mapping(Outer, {"inner": {"sigma_deg": 2, "n": 4}, "names": ["a"]})
    assert obj.inner.sigma_deg == 2.0 and isinstance(obj.inner.sigma_deg, float)
    assert obj.names == ("a",)
    with pytest.raises(CalibError, match="expected an integer"):
        dataclass_from_mapping(Outer, {"inner": {"n": 1.5}})
    with pytest.raises(CalibError, match="not one of gpi, egpi"):
        dataclass_from_mapping(Outer, {"mode": "egpii"})


def test_validate_hook_runs():
    with pytest.raises(CalibError, match="must not contain"):
        dataclass_from_mapping(Outer, {"names": ["bad"]})


def test_empty_config_is_defaults(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text("")
    assert load_config(p) == PipelineConfig()


def test_invalid_toml_is_one_line_error(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text("[fit\n")
    with pytest.raises(CalibError, match="invalid TOML"):
        load_config(p)
    with pytest.raises(CalibError, match="config file not found"):
        load_config(tmp_path / "nope.toml")


def test_configs_are_validated_on_construction():
    """Not only when loaded from TOML: an invalid value fails where it is made."""
    from i2ris_calib.fitting.config import FitConfig
    from i2ris_calib.report.config import ReportConfig

    with pytest.raises(ValueError, match="trf"):
        FitConfig(loss="huber")
    with pytest.raises(ValueError):
        FitConfig(n_operators=0)
    with pytest.raises(ValueError, match="figure_dpi"):
        ReportConfig(figure_dpi=5)
