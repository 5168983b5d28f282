"""The model contract's old home: :mod:`i2ris_calib.model` (``Signals``, ``Parameter``,
``NamedParameters``, the ``Model`` protocol), re-exported so that
``from i2ris_calib.hysteresis.model import Signals`` keeps working."""

from i2ris_calib.model import Model, NamedParameters, Parameter, Signals, analytic_method

__all__ = ["Model", "NamedParameters", "Parameter", "Signals", "analytic_method"]
