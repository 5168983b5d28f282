"""How to read a synced CSV written by another system (TOML section ``[columns]``).

The synced CSV's standard columns (docs/formats.md) are ``time_s, enc_yaw, enc_pitch,
yaw_deg, pitch_deg, status``. A lab's own export names them differently and may count
time from 1970 in ms or give angles in radians: ``[columns]`` (or ``--columns`` of
``fit`` and ``diagnose``) says which of its columns is which and in what unit, so the
file is read as it is. Read by :func:`i2ris_calib.io.synced.read_synced`. The section
itself (:class:`ColumnsConfig`) is declared with the others in :mod:`i2ris_calib.config`.
"""

from __future__ import annotations

import dataclasses

from i2ris_calib.config import ANGLE_UNITS, STANDARD_COLUMNS, ColumnsConfig
from i2ris_calib.errors import CalibError

__all__ = ["ANGLE_UNITS", "STANDARD_COLUMNS", "ColumnsConfig", "parse_columns_option"]


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
