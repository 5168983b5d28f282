# The one list of the public API, with its types for IDEs, notebooks and type checkers.
# At run time the names load lazily (``__getattr__`` in __init__.py), from the module
# this stub imports each from; __init__.py reads these imports and ``__all__`` from here
# (scikit-image's lazy-loader pattern). A new public name is its import (or, for a
# function made in __init__.py, its def) and its ``__all__`` entry; tests/test_api.py
# checks that the two agree and that ``dir(i2ris_calib)`` is ``__all__``.

import os
from collections.abc import Sequence
from typing import Literal

from i2ris_calib.compensation import compensate as compensate
from i2ris_calib.compensation.config import CompensateConfig as CompensateConfig
from i2ris_calib.config import ColumnsConfig as ColumnsConfig
from i2ris_calib.config import PipelineConfig as PipelineConfig
from i2ris_calib.config import RunConfig as RunConfig
from i2ris_calib.data.dataset import Dataset as Dataset
from i2ris_calib.data.dataset import direction_datasets as direction_datasets
from i2ris_calib.data.dataset import make_dataset as make_dataset
from i2ris_calib.diagnosis.config import DiagnosisConfig as DiagnosisConfig
from i2ris_calib.diagnosis.workflow import diagnose as diagnose
from i2ris_calib.diagnosis.workflow import diagnose_from_starts as diagnose_from_starts
from i2ris_calib.errors import CalibError as CalibError
from i2ris_calib.fitting.config import FitConfig as FitConfig
from i2ris_calib.fitting.fit import fit_model as fit_model
from i2ris_calib.fitting.pipeline import fit as fit
from i2ris_calib.fitting.result import FitNote as FitNote
from i2ris_calib.fitting.result import FitResult as FitResult
from i2ris_calib.hysteresis.effects import CATALOGUE as CATALOGUE
from i2ris_calib.hysteresis.effects import add_effect as add_effect
from i2ris_calib.hysteresis.models import continuous_egpi_model as continuous_egpi_model
from i2ris_calib.hysteresis.models import egpi_model as egpi_model
from i2ris_calib.hysteresis.models import gpi_model as gpi_model
from i2ris_calib.hysteresis.models import i2ris_egpi_model as i2ris_egpi_model
from i2ris_calib.hysteresis.registry import MODEL_KINDS as MODEL_KINDS
from i2ris_calib.hysteresis.registry import model_for_kind as model_for_kind
from i2ris_calib.io.online import Compensator as Compensator
from i2ris_calib.model import Parameter as Parameter
from i2ris_calib.model import Signals as Signals
from i2ris_calib.report.config import ReportConfig as ReportConfig
from i2ris_calib.simulation.config import SimulationConfig as SimulationConfig
from i2ris_calib.sync.config import SyncConfig as SyncConfig
from i2ris_calib.tracking.config import TrackingConfig as TrackingConfig

__version__: str

def load_synced(
    path: str | os.PathLike[str],
    axis: Literal["yaw", "pitch"],
    config: FitConfig | None = None,
    directions: Sequence[str] | None = None,
    columns: ColumnsConfig | None = None,
) -> list[Dataset]:
    """The datasets ``i2ris-calib fit`` fits on a synced CSV (the paper's split, one per
    motion direction, or the one signed ``±`` dataset when the recording calls for it:
    the same rule as the command line); ``directions``: only these; ``columns``: a lab
    file's column mapping (``ColumnsConfig``, docs/formats.md)."""

def load_config(path: str | os.PathLike[str] | None = None) -> PipelineConfig:
    """The pipeline TOML at ``path`` (defaults when None) as a PipelineConfig."""

__all__ = [
    "__version__",
    "gpi_model",
    "i2ris_egpi_model",
    "continuous_egpi_model",
    "egpi_model",
    "model_for_kind",
    "MODEL_KINDS",
    "Parameter",
    "Signals",
    "Dataset",
    "make_dataset",
    "direction_datasets",
    "fit",
    "fit_model",
    "FitResult",
    "FitNote",
    "FitConfig",
    "diagnose",
    "diagnose_from_starts",
    "add_effect",
    "CATALOGUE",
    "compensate",
    "Compensator",
    "PipelineConfig",
    "RunConfig",
    "ColumnsConfig",
    "TrackingConfig",
    "SyncConfig",
    "DiagnosisConfig",
    "CompensateConfig",
    "ReportConfig",
    "SimulationConfig",
    "CalibError",
    "load_synced",
    "load_config",
]
