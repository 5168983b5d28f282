"""The model kinds by name: what a stage may know of a kind without importing its model.

One row per kind: its name, labels, where its class lives, and the flags every stage
reads (which input it needs, whether it has an inverse, whether ``diagnose`` starts
from it, ...). Nothing here imports numpy or a model, so the command line's ``--help``
reads the kinds from this table directly. :mod:`i2ris_calib.hysteresis.registry` joins
each row to its class, factory, start recipe and fixed parameters (``ModelKind``); the
other stages read the registry. Kind names are written out here and in the registry
only (tests/test_architecture.py keeps them out of the other layers).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class KindName:
    """One model kind's name, labels, class location and flags (the meaning of each
    flag: :class:`i2ris_calib.hysteresis.registry.ModelKind`)."""

    kind: str
    label: str
    report_name: str
    model: str = ""  # "module:Class" under i2ris_calib.hysteresis ("": not built)
    nested: str | None = None
    inverse: str | None = None
    signed: bool = False
    paper: bool = False
    diagnosis_start: bool = False
    on_signed: bool = False
    uses_deadband: bool = False
    coupled: bool = False
    with_coupling: bool = True
    method: str | None = None
    output_steps: bool = False
    n_starts: str = "n_starts"


#: The model families the compensation kernel inverts, in the order of its kind codes
#: (``compensation/kernel.py``, ``KIND_*``); a row's ``inverse`` names one (a coupled
#: kind: its own tendons', the coupling inverted with them). The online compensator's
#: JSON names them (``kernel_kind``).
INVERSE_FAMILIES = ("gpi", "egpi", "egpi_c", "agpi")

#: Every kind, in fitting order (a kind's nested kind comes before it).
NAMES: tuple[KindName, ...] = (
    KindName("gpi", "GPI", "GPI", "models:GPIModel", n_starts="n_starts_gpi", inverse="gpi",
             paper=True, diagnosis_start=True, on_signed=True),
    KindName("egpi", "EGPI", "EGPI", "models:I2RISEGPIModel", nested="gpi", inverse="egpi",
             paper=True, diagnosis_start=True, uses_deadband=True, output_steps=True),
    KindName("egpi_c", "EGPI_C", "EGPI_C", "models:ContinuousEGPIModel", nested="gpi",
             inverse="egpi_c", uses_deadband=True),
    KindName("agpi", "two-tendon GPI", "two-tendon GPI", "two_tendon:TwoTendonGPIModel",
             n_starts="n_starts_gpi", signed=True, on_signed=True, diagnosis_start=True,
             inverse="agpi"),
    KindName("agpi_coupled", "two-tendon GPI + coupling",
             "two-tendon GPI + hysteretic coupling to the other motor",
             "coupled:CoupledTwoTendonModel", n_starts="n_starts_gpi", nested="agpi",
             signed=True, coupled=True, inverse="agpi"),
    KindName("maxwell_slip", "PI / Maxwell slip", "Prandtl-Ishlinskii / Maxwell slip",
             "slip:SlipModel", signed=True, on_signed=True, diagnosis_start=True,
             with_coupling=False, method="trf"),
    KindName("bouc_wen", "Bouc-Wen", "Bouc-Wen (one smooth loop)", "bouc_wen:BoucWenModel",
             signed=True, on_signed=True, diagnosis_start=True, with_coupling=False),
    KindName("diagnosed", "DIAGNOSED", "EGPI + diagnosed effects"),
)  # fmt: skip

BY_NAME = {k.kind: k for k in NAMES}

#: Kinds a factory builds (every kind but ``"diagnosed"``), in fitting order.
BUILT_KINDS = tuple(k.kind for k in NAMES if k.model)
#: Kinds of a motion-direction dataset (the paper's split).
MODEL_KINDS = tuple(k.kind for k in NAMES if k.model and not k.signed)
#: Kinds that need the whole signed input of an axis.
SIGNED_ONLY_KINDS = tuple(k.kind for k in NAMES if k.model and k.signed)
#: Kinds the compensation stage inverts.
INVERSE_KINDS = tuple(k.kind for k in NAMES if k.inverse)
#: Starting models of ``diagnose``.
DIAGNOSIS_STARTS = tuple(k.kind for k in NAMES if k.diagnosis_start)
#: A model saved by ``diagnose`` and refitted by ``fit --model-file``.
DIAGNOSED = "diagnosed"
#: The continuous EGPI: preferred over a kind whose output steps at its flag point
#: (``output_steps``) within a margin (fitting/decision.py).
CONTINUOUS_EGPI = "egpi_c"
#: The paper's two models (its Tables 1-2), in the paper's row order (EGPI, GPI).
PAPER_KINDS = tuple(k.kind for k in reversed(NAMES) if k.paper)
#: The model the paper proposes, its I2RIS EGPI: the paper's kind with a nested kind.
PAPER_MODEL = next(k.kind for k in NAMES if k.paper and k.nested)
#: The paper's baseline, the GPI nested in its EGPI (the report's GPI / EGPI ratio).
PAPER_BASELINE = BY_NAME[PAPER_MODEL].nested
#: The truth of a simulated paper-protocol session, per motion direction: the paper's
#: EGPI (truth.json ``datasets[].model``).
SESSION_TRUTH = PAPER_MODEL
#: The truth of the simulated lab, per axis: the two-tendon GPI, the first signed-only
#: kind (simulation/lab.py, two_motor.py; truth.json ``lab.model``).
LAB_TRUTH = SIGNED_ONLY_KINDS[0]
