"""Fixtures of the diagnosis tests: a trivial linear model and synthetic cases."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import paper_like_params
from i2ris_calib.model import Parameter, Signals


@dataclass(frozen=True)
class LinearModel:
    """y = gain * v + offset: no hysteresis, so effect transforms can be checked by hand."""

    name: str = "linear"
    parameters: tuple[Parameter, ...] = (
        Parameter("gain", value=0.01, lower=0.0, upper=1.0, unit="deg/count"),
        Parameter("offset", value=0.0, lower=-100.0, upper=100.0, unit="deg"),
    )

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        return values[0] * np.asarray(signals.v, float) + values[1]

    def with_values(self, values):
        return replace(
            self,
            parameters=tuple(
                replace(p, value=float(x)) for p, x in zip(self.parameters, values, strict=True)
            ),
        )


@pytest.fixture
def linear() -> LinearModel:
    return LinearModel()


@pytest.fixture
def egpi():
    """The paper-like yaw+ EGPI (truth values)."""
    return i2ris_egpi_model(**paper_like_params("yaw+"))
