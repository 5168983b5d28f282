"""In-memory contents of a run folder, as read by :mod:`i2ris_calib.io.run_folder`.

Every field is optional: a stage that has not run leaves its field ``None`` and
the report states it. The loader has already checked the shapes of what is
present (required columns, JSON structure), so builders can index safely.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pandas as pd


@dataclass(frozen=True)
class FitData:
    """One ``fit/<axis>/`` folder.

    Attributes
    ----------
    axis : str
        ``"yaw"`` or ``"pitch"`` (the folder name).
    fit : dict
        Parsed ``fit.json`` (schema ``i2ris-calib.fit/1``).
    predictions : DataFrame or None
        ``predictions.csv``: every sample of the recording once per dataset: dataset,
        time_s (s), v (the dataset's input, counts), theta_deg (measured angle in the
        dataset's convention, deg, NaN when not measured), gpi_deg, egpi_deg,
        egpi_c_deg [, diagnosed_deg] (model outputs, deg), split (fit | holdout |
        other: the other direction's samples); ``None`` when absent.
    """

    axis: str
    fit: dict[str, Any]
    predictions: pd.DataFrame | None = None


@dataclass(frozen=True)
class DiagnosisData:
    """One ``diagnose/<axis>/`` folder.

    Attributes
    ----------
    axis : str
        Folder name.
    diagnosis : dict
        Parsed ``diagnosis.json``.
    markdown : str or None
        The ``diagnosis.md`` fragment, when present.
    images : dict
        Relative path (as written in diagnosis.json / diagnosis.md) -> PNG bytes.
    missing_images : tuple of str
        Images listed in diagnosis.json that were not found.
    """

    axis: str
    diagnosis: dict[str, Any]
    markdown: str | None = None
    images: dict[str, bytes] = field(default_factory=dict)
    missing_images: tuple[str, ...] = ()


@dataclass(frozen=True)
class CompensationData:
    """The ``compensate/`` folder written by ``run`` with a ``[compensate] target``.

    Attributes
    ----------
    doc : dict
        Parsed ``compensate.json`` (schema ``i2ris-calib.compensate/1``).
    commands : DataFrame
        ``commands.csv``: time_s (s), enc_<axis> (counts), predicted_<axis>_deg (deg),
        reachable (0/1).
    target : DataFrame or None
        ``target.csv``: the target as given (time_s, <axis>_deg).
    """

    doc: dict[str, Any]
    commands: pd.DataFrame
    target: pd.DataFrame | None = None


@dataclass(frozen=True)
class RunData:
    """Everything the report shows, read from one run folder.

    Attributes
    ----------
    name : str
        Run (session) name, the folder name.
    angles : DataFrame or None
        ``track/angles.csv`` (frame, time_s, yaw_deg, pitch_deg, status, reproj_err_px, ...).
    track : dict or None
        ``track/track.json``.
    sync : dict or None
        ``sync/sync.json``.
    synced : DataFrame or None
        ``sync/synced.csv`` (time_s, enc_yaw, enc_pitch, yaw_deg, pitch_deg, status, frame).
    fits : tuple of FitData
        One per ``fit/<axis>/fit.json`` found, yaw first, then pitch, then others by name.
    diagnoses : tuple of DiagnosisData
        One per ``diagnose/<axis>/diagnosis.json`` found.
    compensation : CompensationData or None
        ``compensate/`` when ``run`` was given a target.
    absent : dict
        Input label (e.g. ``"track/angles.csv"``) -> reason it is not shown.
    fit_only : bool
        Read from a ``fit`` output folder (fit.json + predictions.csv), not a run
        folder: the report holds the model sections alone.
    """

    name: str
    angles: pd.DataFrame | None = None
    track: dict[str, Any] | None = None
    sync: dict[str, Any] | None = None
    synced: pd.DataFrame | None = None
    fits: tuple[FitData, ...] = ()
    diagnoses: tuple[DiagnosisData, ...] = ()
    compensation: CompensationData | None = None
    absent: dict[str, str] = field(default_factory=dict)
    fit_only: bool = False
