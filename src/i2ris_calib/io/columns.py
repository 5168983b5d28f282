"""How to read a synced CSV written by another system (TOML section ``[columns]``).

The synced CSV's standard columns (docs/formats.md) are ``time_s, enc_yaw, enc_pitch,
yaw_deg, pitch_deg, status``. A lab's own export names them differently and may count
time from 1970 in ms or give angles in radians: ``[columns]`` (or ``--columns`` of
``fit`` and ``diagnose``) says which of its columns is which and in what unit, so the
file is read as it is. Read by :func:`i2ris_calib.io.synced.read_synced`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from i2ris_calib._validate import validated_config
from i2ris_calib.errors import CalibError

#: the synced CSV's own column names, in file order (the keys naming a column)
STANDARD_COLUMNS = ("time_s", "enc_yaw", "enc_pitch", "yaw_deg", "pitch_deg", "status")
ANGLE_UNITS = ("deg", "rad")


@dataclass(frozen=True)
class ColumnsConfig:
    """Which column of the file is which, and the file's units.

    Each column key is a standard synced-CSV column; its value is that column's
    header in the file (compared with surrounding spaces stripped). Default: the
    standard names, i.e. a synced CSV as ``sync`` writes it.

    Attributes
    ----------
    time_s, enc_yaw, enc_pitch, yaw_deg, pitch_deg, status : str
        Header of the file's column holding the sample time, the yaw and pitch motor
        encoders (counts), the measured yaw and pitch angles and the tracking status.
        A column named here other than its standard name must be in the file; the
        other axis's columns and ``status`` may be absent under their standard names.
    time_unit_s : float
        Seconds per unit of the time column: 1 for s, 0.001 for ms, 1e-9 for ns.
        Times from 1970 (epoch clocks) are read at full precision and counted from
        the first sample (docs/formats.md).
    angle_unit : str
        Unit of the angle columns: ``"deg"`` or ``"rad"`` (converted to degrees).
    """

    time_s: str = "time_s"
    enc_yaw: str = "enc_yaw"
    enc_pitch: str = "enc_pitch"
    yaw_deg: str = "yaw_deg"
    pitch_deg: str = "pitch_deg"
    status: str = "status"
    time_unit_s: float = 1.0
    angle_unit: str = "deg"

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on a unit no file has, an empty name or one column read twice."""
        if not (math.isfinite(self.time_unit_s) and self.time_unit_s > 0):
            raise ValueError(
                f"time_unit_s = {self.time_unit_s} must be a number > 0 (seconds "
                "per unit of the time column: 1 for s, 0.001 for ms, 1e-9 for ns)"
            )
        if self.angle_unit not in ANGLE_UNITS:
            raise ValueError(f'angle_unit = \'{self.angle_unit}\' must be "deg" or "rad"')
        seen: dict[str, str] = {}
        for key in STANDARD_COLUMNS:
            name = getattr(self, key).strip()
            if not name:
                raise ValueError(f"{key} is empty; give the header of the file's {key} column")
            if name in seen:
                raise ValueError(
                    f"{seen[name]} and {key} both read column '{name}'; "
                    "each column of the file can be only one of them"
                )
            seen[name] = key

    def mapping(self) -> dict[str, str]:
        """``{standard name: header in the file}`` (stripped) for every column key."""
        return {key: getattr(self, key).strip() for key in STANDARD_COLUMNS}

    def is_mapped(self, key: str) -> bool:
        """True when column ``key`` is read under another name than its standard one."""
        return getattr(self, key).strip() != key


def parse_columns_option(text: str, base: ColumnsConfig | None = None) -> ColumnsConfig:
    """``base`` (the config's ``[columns]``) with the ``--columns`` option applied.

    ``text`` is ``KEY=VALUE`` pairs separated by commas, the keys and values of
    ``[columns]``: ``"time_s=Img TS,enc_yaw=Encoder counts 0,time_unit_s=0.001"``.
    Spaces around keys and values are ignored; a header containing a comma must be
    given in the config file instead. Unknown keys are rejected with the closest
    valid one suggested (as for the config file).
    """
    from i2ris_calib.io.config_io import dataclass_from_mapping, dataclass_to_dict

    base = ColumnsConfig() if base is None else base
    given: dict[str, object] = {}
    for item in (s for s in text.split(",") if s.strip()):
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key:
            raise CalibError(
                f"--columns: '{item.strip()}' is not KEY=VALUE; give e.g. "
                '--columns "time_s=Img TS,enc_yaw=Encoder counts 0,yaw_deg=yaws" (docs/formats.md)'
            )
        if key in given:
            raise CalibError(f"--columns: '{key}' is given twice; give each key once")
        given[key] = value
    if not given:
        raise CalibError(
            '--columns is empty; give KEY=VALUE pairs, e.g. "time_s=Img TS,yaw_deg=yaws"'
        )
    floats = {f.name for f in dataclasses.fields(ColumnsConfig) if f.type in (float, "float")}
    for key in floats & given.keys():
        try:
            given[key] = float(str(given[key]))
        except ValueError:
            raise CalibError(
                f"--columns: {key}={given[key]} is not a number (e.g. {key}=0.001)"
            ) from None
    return dataclass_from_mapping(
        ColumnsConfig, {**dataclass_to_dict(base), **given}, where="--columns"
    )
