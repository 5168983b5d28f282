"""Configuration of feedforward compensation in ``run`` (TOML section ``[compensate]``,
see docs/compensate.md)."""

from __future__ import annotations

from dataclasses import dataclass

from i2ris_calib._validate import validated_config
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.hysteresis.registry import INVERSE_KINDS

#: The kinds compensation inverts (the registry's ``inverse``) and ``"diagnosed"``
_KINDS = ("", *INVERSE_KINDS, DIAGNOSED)
#: how the commands start (`--conditioning`, docs/compensate.md "Start state")
CONDITIONING = ("auto", "sweep", "none")
_DATASETS = ("yaw+", "yaw-", "yaw±", "pitch+", "pitch-", "pitch±")


@dataclass(frozen=True)
class CompensateConfig:
    """Settings of the compensation stage of ``run``. Units are in the field names.

    Attributes
    ----------
    target : str
        Target CSV (``time_s``, ``<axis>_deg``; docs/compensate.md). Empty: no
        compensation stage. A relative path is looked up in the session folder first,
        then in the current folder.
    datasets : tuple of str
        Which fitted direction inverts each axis of the target (``"yaw+"``, ...). Empty:
        per axis in the target, ``"+"`` when the target's median angle is >= 0, else
        ``"-"``.
    model : str
        ``gpi``, ``egpi``, ``egpi_c`` or ``diagnosed``; empty: the model fit.json
        recommends (its ``decision``; docs/compensate.md, "Which model").
    max_counts_per_s : float
        Motor rate limit (counts/s); 0: the fit's fastest input move (fit.json
        ``max_input_rate_counts_per_s``); ``inf``: none.
    time_unit_s : float
        Seconds per unit of the target's ``time_s`` (0.001 for ms).
    conditioning : str
        How the commands start (docs/compensate.md, "Start state"): ``auto`` (a
        conditioning sweep over the fitted range when a fit's recording started
        mid-loop, so the model's state at rest is not known), ``sweep`` (always) or
        ``none`` (the robot is assumed relaxed at the start counts).
    """

    target: str = ""
    datasets: tuple[str, ...] = ()
    model: str = ""
    max_counts_per_s: float = 0.0
    time_unit_s: float = 1.0
    conditioning: str = "auto"

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
        if self.model not in _KINDS:
            raise ValueError(
                f"model '{self.model}' is not one of {', '.join(_KINDS[1:])} (or empty)"
            )
        bad = [d for d in self.datasets if d not in _DATASETS]
        if bad:
            raise ValueError(f"datasets: unknown {bad}; use {', '.join(_DATASETS)}")
        if len({d[:-1] for d in self.datasets}) != len(self.datasets):
            raise ValueError("datasets: at most one direction per axis")
        if self.max_counts_per_s < 0:
            raise ValueError(
                "max_counts_per_s must be >= 0 (0 = the fit's fastest input move, inf = none)"
            )
        if self.conditioning not in CONDITIONING:
            raise ValueError(
                f"conditioning '{self.conditioning}' is not one of {', '.join(CONDITIONING)}"
            )
        if not (self.time_unit_s > 0 and self.time_unit_s < float("inf")):
            raise ValueError("time_unit_s must be a number > 0 (seconds per unit of time_s)")
