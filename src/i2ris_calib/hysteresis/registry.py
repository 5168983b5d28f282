"""The one registry of model kinds: the name a config, a command line or a saved file
uses (``"gpi"``, ``"egpi"``, ``"egpi_c"``, ...) -> everything the stages need to know.

Each kind is one :class:`ModelKind` row of :data:`KINDS`: its factory and class, its
label in the terminal and in the report, its start recipe (:mod:`.start`), the
``[fit]`` settings it reads (held parameters, number of starts), the kind whose fit
is nested in it (a start), its inverse in the compensation stage, and whether it
needs the whole signed input of an axis. The fitting, diagnosis, compensation and
report stages and the file readers read this table; adding a built-in kind is its
module plus one row here (and its docs and tests).

Every place that turns a kind into a model goes through :func:`model_for_kind`, so
the defaults (``n`` operators, the ``v'`` dead band) are the same everywhere.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from operator import attrgetter

from i2ris_calib._validate import describe
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.bouc_wen import (
    BoucWenModel,
    bouc_wen_fixed,
    bouc_wen_model,
    bouc_wen_starts,
)
from i2ris_calib.hysteresis.coupled import (
    CoupledTwoTendonModel,
    coupled_fixed,
    coupled_starts,
    coupled_two_tendon_model,
)
from i2ris_calib.hysteresis.kinds import BY_NAME, DIAGNOSED, KindName
from i2ris_calib.hysteresis.models import (
    ContinuousEGPIModel,
    GPIModel,
    I2RISEGPIModel,
    ParametricModel,
    check_settings,
    checked_values,
    continuous_egpi_model,
    gpi_model,
    i2ris_egpi_model,
)
from i2ris_calib.hysteresis.slip import SlipModel, slip_fixed, slip_model, slip_starts
from i2ris_calib.hysteresis.start import start_values
from i2ris_calib.hysteresis.two_tendon import (
    TwoTendonGPIModel,
    two_tendon_fixed,
    two_tendon_gpi_model,
    two_tendon_starts,
)

#: Defaults of :func:`model_for_kind` (those of the model factories)
DEFAULT_N_OPERATORS = 30
DEFAULT_DEADBAND_COUNTS = 2.0
#: Thresholds of the PI / Maxwell-slip kind (its own: one free weight each, so half
#: GPI's 30 keeps the fit and a diagnosis from it fast; 0.45 / 15 of the input range
#: apart)
SLIP_THRESHOLDS = 15


@dataclass(frozen=True)
class ModelKind(KindName):
    """One model kind and what every stage needs to know about it.

    Attributes
    ----------
    kind : str
        The name in configs, on the command line, in fit.json and final_model.json.
    label : str
        Row label in the terminal's results table.
    report_name : str
        Row label in the report's tables.
    model : str
        Where its class lives, ``"module:Class"`` under ``i2ris_calib.hysteresis``
        (the names table, :mod:`~i2ris_calib.hysteresis.kinds`; "" when not built).
    factory : callable or None
        ``factory(n=..., deadband_counts=...)`` -> an unfitted model with default
        values (``deadband_counts`` only when ``uses_deadband``); None for
        ``"diagnosed"`` (a model saved by ``diagnose``, rebuilt from its file).
    model_class : type or None
        The class the factory returns (a model's kind is found from its class).
    start : callable or None
        The data-driven start recipe ``start(model, v, theta_deg, n_starts, rng,
        deadband)`` -> list of start vectors, shape (p,) each.
    fixed : callable
        ``fixed(fit_config)`` -> names of the parameters held at their start value.
    n_starts : str
        The ``[fit]`` setting giving its number of data-driven starts.
    nested : str or None
        Kind whose fit, mapped into this kind, is one more start (GPI in EGPI).
    inverse : str or None
        Model family the compensation kernel inverts (one of
        :data:`~i2ris_calib.hysteresis.kinds.INVERSE_FAMILIES`: ``"gpi"``, ``"egpi"``,
        ``"egpi_c"``, ``"agpi"``; a ``coupled`` kind: its own tendons', given the other
        motor's commands); None: no inverse.
    signed : bool
        Needs the whole signed input of an axis (dataset ``"±"``).
    paper : bool
        One of the paper's two models (compared with its Tables 1-2).
    diagnosis_start : bool
        A starting model of ``diagnose``.
    on_signed : bool
        Fitted by default on a signed dataset (``"±"``).
    uses_deadband : bool
        Its factory takes the ``v'`` dead band.
    coupled : bool
        Reads the other motor's input (``Signals.v_other``): fitted by default when the
        other motor moves while this one does (:mod:`i2ris_calib.data.coupling`); its
        ``start`` is ``start(model, signals, theta, nested_params, n_starts, rng,
        deadband)`` -> (model, starts).
    n_operators : int or None
        Its own number of thresholds in the default path (:func:`model_for_kind`
        without ``n``, the fitting stage), instead of ``[fit] n_operators`` (GPI's);
        None: that setting.
    method : str or None
        Fit method this kind needs, overriding ``[fit] method`` (``"trf"``: parameters
        bounded by their physics, e.g. a stiffness >= 0, that the unbounded LM would
        leave at every fit); None: the configured one.
    with_coupling : bool
        Also fitted on a signed input whose other motor moves with this one (then the
        axis is a tendon axis moved by two motors: a one-element kind over the signed
        input, without the other motor's input, is left out; :func:`signed_kinds`).
    output_steps : bool
        Its output steps at its flag point ``v_f`` (the paper's EGPI switches envelope
        families there): the report prefers the continuous EGPI_C within a margin, and
        compensate says where a stepping output misses the target.
    """

    factory: Callable[..., ParametricModel] | None = None
    model_class: type | None = None
    start: Callable | None = None
    fixed: Callable[[object], tuple[str, ...]] = lambda config: ()
    n_operators: int | None = None


def _row(kind: str, factory, model_class, **behaviour) -> ModelKind:
    """The registry row of ``kind``: its name, labels and flags from the names table
    (:mod:`~i2ris_calib.hysteresis.kinds`), joined to its factory, class and recipes."""
    name = BY_NAME[kind]
    flags = {f.name: getattr(name, f.name) for f in fields(KindName)}
    if model_class is not None and f"{model_class.__module__}:{model_class.__name__}" != (
        f"i2ris_calib.hysteresis.{name.model}"
    ):
        raise TypeError(f"kinds.py says {kind} is {name.model}, not {model_class.__name__}")
    return ModelKind(factory=factory, model_class=model_class, **flags, **behaviour)


#: Every kind, in fitting order (a kind's nested kind comes before it). Tables list
#: them in the reverse order (:func:`table_order`).
KINDS: tuple[ModelKind, ...] = (
    _row("gpi", gpi_model, GPIModel, start=start_values, fixed=attrgetter("fixed_gpi")),
    _row("egpi", i2ris_egpi_model, I2RISEGPIModel, start=start_values,
         fixed=attrgetter("fixed_egpi")),
    _row("egpi_c", continuous_egpi_model, ContinuousEGPIModel, start=start_values,
         fixed=attrgetter("fixed_egpi")),
    _row("agpi", two_tendon_gpi_model, TwoTendonGPIModel, start=two_tendon_starts,
         fixed=two_tendon_fixed),
    _row("agpi_coupled", coupled_two_tendon_model, CoupledTwoTendonModel,
         start=coupled_starts, fixed=coupled_fixed),
    _row("maxwell_slip", slip_model, SlipModel, start=slip_starts, fixed=slip_fixed,
         n_operators=SLIP_THRESHOLDS),
    _row("bouc_wen", bouc_wen_model, BoucWenModel, start=bouc_wen_starts, fixed=bouc_wen_fixed),
    _row(DIAGNOSED, None, None),
)  # fmt: skip

_BY_NAME = {k.kind: k for k in KINDS}

#: Kinds a factory builds (every kind but ``"diagnosed"``), in fitting order.
BUILT_KINDS = tuple(k.kind for k in KINDS if k.factory is not None)

#: Model kinds of a motion-direction dataset: GPI (Eq1-3), the paper's I2RIS EGPI
#: (Eq16-23) and the continuous EGPI (docs/models.md). ``"all"`` on the command line
#: means these on a per-direction fit.
MODEL_KINDS = tuple(k.kind for k in KINDS if k.factory is not None and not k.signed)

#: Kinds a fit.json / compensation may name: the built kinds and ``"diagnosed"``.
ALL_KINDS = tuple(k.kind for k in KINDS)

#: Kinds the compensation stage inverts (a ``"diagnosed"`` model: when its base is one).
INVERSE_KINDS = tuple(k.kind for k in KINDS if k.inverse)

#: Kinds fitted by default on a signed dataset (``"±"``, one model over the whole
#: signed input of an axis), in fitting order: one GPI over the signed input, the
#: two-tendon GPI, and the one-loop kinds (PI / Maxwell slip, Bouc-Wen). ``"all"`` on a
#: signed fit means these.
SIGNED_KINDS = tuple(k.kind for k in KINDS if k.on_signed)


def signed_kinds(coupled: bool = False) -> tuple[str, ...]:
    """The kinds fitted by default on a signed dataset: :data:`SIGNED_KINDS`, without
    those not fitted when the other motor moves with this one (``coupled``; the
    coupled model, :data:`COUPLED_DEFAULT`, is then added by the model choice)."""
    return tuple(k.kind for k in KINDS if k.on_signed and (k.with_coupling or not coupled))


#: The default model of a signed dataset: the first signed-only kind (two-tendon GPI).
SIGNED_DEFAULT = next(k.kind for k in KINDS if k.signed)

#: The default model of a signed dataset when the other motor moves while this one
#: does: the two-tendon GPI with coupling to the other motor (fitted after its nested
#: kind, :data:`SIGNED_DEFAULT`).
COUPLED_DEFAULT = next(k.kind for k in KINDS if k.coupled)

#: Starting models of ``diagnose``.
DIAGNOSIS_STARTS = tuple(k.kind for k in KINDS if k.diagnosis_start)


def diagnosis_starts(signed: bool) -> tuple[str, ...]:
    """The starting models of ``diagnose --start auto`` on a dataset: the signed-only
    starting kinds (the two-tendon GPI) on a signed dataset, the others (GPI, EGPI) on
    a motion-direction dataset."""
    return tuple(k.kind for k in KINDS if k.diagnosis_start and k.signed == bool(signed))


def kind_info(kind: str) -> ModelKind:
    """The registry row of ``kind``; CalibError for an unknown kind."""
    if not isinstance(kind, str) or kind not in _BY_NAME:
        raise CalibError(f"unknown model '{kind}'; use {', '.join(BUILT_KINDS)} or all")
    return _BY_NAME[kind]


def kind_of(model: object) -> ModelKind | None:
    """The registry row of a model's class (its nearest registered base class), or
    None (a general EGPI, a model extended by effects: see ``hysteresis.effects.base_of``)."""
    for cls in type(model).__mro__:
        for k in KINDS:
            if k.model_class is cls:
                return k
    return None


def table_order(kinds) -> list[str]:
    """``kinds`` in table order (the reverse of the fitting order: ``"diagnosed"``
    first, GPI last); names not in the registry are left out."""
    return [k.kind for k in reversed(KINDS) if k.kind in kinds]


def fit_order(kinds) -> list[str]:
    """``kinds`` in fitting order (a kind's nested kind first); names not in the
    registry at the end, in their order."""
    return [k for k in ALL_KINDS if k in kinds] + [k for k in kinds if k not in _BY_NAME]


def start_recipe(model: object) -> Callable | None:
    """The data-driven start recipe of a model (its kind's ``start``), or None."""
    info = kind_of(model)
    return None if info is None else info.start


def model_for_kind(
    kind: str,
    n: int | None = None,
    deadband_counts: float = DEFAULT_DEADBAND_COUNTS,
    **values: float,
) -> ParametricModel:
    """The model of ``kind`` with ``n`` thresholds and the given parameter values.

    Parameters
    ----------
    kind : str
        One of :data:`BUILT_KINDS` (``"gpi"``, ``"egpi"``, ``"egpi_c"``, ...).
    n : int, optional
        Number of non-zero thresholds (n + 1 operators, Eq14); default: the kind's own
        (:attr:`ModelKind.n_operators`), else :data:`DEFAULT_N_OPERATORS`.
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
        raise CalibError(f"{func}: kind is {describe(kind)}; give one of {', '.join(BUILT_KINDS)}")
    info = kind_info(kind)
    if info.factory is None:
        raise CalibError(f"unknown model '{kind}'; use {', '.join(BUILT_KINDS)} or all")
    if n is None:
        n = info.n_operators or DEFAULT_N_OPERATORS
    check_settings(func, n, deadband_counts)
    if info.uses_deadband:
        model = info.factory(n=n, deadband_counts=deadband_counts)
    else:
        model = info.factory(n=n)
    return checked_values(func, model, values)
