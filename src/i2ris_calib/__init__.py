"""i2ris-calib: calibration pipeline for the I2RIS tendon-driven snake robot.

Stages (each a subpackage of pure functions on arrays and frozen dataclasses):
``simulation`` (synthetic sessions), ``tracking`` (ArUco pose -> pitch/yaw),
``sync`` (camera clock -> encoder clock), ``hysteresis`` (GPI/EGPI models),
``fitting`` (Levenberg-Marquardt), ``diagnosis`` (model-discrepancy workflow),
``report`` (tables and figures). ``io`` reads and writes files; ``cli`` is the
thin command-line layer.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("i2ris-calib")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
