"""The one registry of model kinds: the name a config, a command line or a saved file
uses (``"gpi"``, ``"egpi"``, ``"egpi_c"``) -> the model.

Every place that turns a kind into a model (the fitting stage, saved fits, the
compensation and diagnosis stages) goes through :func:`model_for_kind`, so the
defaults (``n`` operators, the ``v'`` dead band) are the same everywhere.
"""

from __future__ import annotations

from i2ris_calib._validate import describe
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.models import (
    ParametricModel,
    check_settings,
    checked_values,
    continuous_egpi_model,
    gpi_model,
    i2ris_egpi_model,
)

#: Model kinds: GPI (Eq1-3), the paper's I2RIS EGPI (Eq16-23) and the continuous EGPI
#: (docs/models.md). ``"all"`` on the command line means all three.
MODEL_KINDS = ("gpi", "egpi", "egpi_c")

#: Defaults of :func:`model_for_kind` (those of the model factories)
DEFAULT_N_OPERATORS = 30
DEFAULT_DEADBAND_COUNTS = 2.0


def model_for_kind(
    kind: str,
    n: int = DEFAULT_N_OPERATORS,
    deadband_counts: float = DEFAULT_DEADBAND_COUNTS,
    **values: float,
) -> ParametricModel:
    """The model of ``kind`` with ``n`` thresholds and the given parameter values.

    Parameters
    ----------
    kind : {"gpi", "egpi", "egpi_c"}
    n : int
        Number of non-zero thresholds (n + 1 operators, Eq14).
    deadband_counts : float
        ``v'`` dead band (input unit) of the EGPI kinds; GPI has none.
    **values : float
        Parameter values by name (the others keep the factory defaults).

    Raises
    ------
    CalibError
        Unknown kind, unknown parameter name, a value that is not a finite number,
        ``n`` not an integer >= 1, ``deadband_counts`` not a number >= 0.
    """
    func = "model_for_kind"
    if not isinstance(kind, str):
        raise CalibError(f"{func}: kind is {describe(kind)}; give one of {', '.join(MODEL_KINDS)}")
    factories = {"gpi": gpi_model, "egpi": i2ris_egpi_model, "egpi_c": continuous_egpi_model}
    if kind not in factories:
        raise CalibError(f"unknown model '{kind}'; use {', '.join(MODEL_KINDS)} or all")
    check_settings(func, n, deadband_counts)
    if kind == "gpi":
        model = gpi_model(n=n)
    else:
        model = factories[kind](n=n, deadband_counts=deadband_counts)
    return checked_values(func, model, values)
