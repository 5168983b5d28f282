"""i2ris-calib: calibration pipeline for the I2RIS tendon-driven snake robot.

Stages (each a subpackage of pure functions on arrays and frozen dataclasses):
``simulation`` (synthetic sessions), ``tracking`` (ArUco pose -> pitch/yaw),
``sync`` (camera clock -> encoder clock), ``hysteresis`` (GPI/EGPI models),
``fitting`` (Levenberg-Marquardt), ``diagnosis`` (model-discrepancy workflow),
``compensation`` (inverse models), ``report`` (tables and figures). ``io`` reads and
writes files; ``commands`` runs a stage per command (files in, stage, files out);
``cli`` is the thin command-line layer.

The Python API (docs/api.md) is importable from here; names load on first use, so
``import i2ris_calib`` stays cheap (the CLI's ``--help`` does not load numba, scipy,
OpenCV or matplotlib). ``__init__.pyi`` is the one list of them: it declares them with
their real types for IDEs and type checkers, and this module reads its ``__all__`` and
the module each name is imported from (scikit-image's lazy-loader pattern, its
``attach_stub``); ``dir(i2ris_calib)`` lists exactly ``__all__``::

    from i2ris_calib import i2ris_egpi_model, fit, load_synced
    data = load_synced("synced.csv", "yaw")[0]      # the yaw+ dataset, whole history
    res = fit(i2ris_egpi_model(), data)              # data-driven starts, LM
    print(res.fit_report())
"""

from importlib import import_module as _import_module
from importlib.metadata import PackageNotFoundError as _PackageNotFoundError
from importlib.metadata import version as _version

try:
    __version__ = _version("i2ris-calib")
except _PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"


def _stub_names() -> tuple[dict[str, str], list[str]]:
    """The public names as ``__init__.pyi`` declares them.

    Returns
    -------
    api : dict
        Public name -> the module it is imported from (the stub's ``from module import
        name as name`` lines).
    names : list of str
        The stub's ``__all__``: those names, ``__version__`` and the functions the stub
        defines (:data:`_IO`, made here).
    """
    import ast
    from pathlib import Path

    tree = ast.parse(Path(__file__).with_suffix(".pyi").read_text(encoding="utf-8"))
    api: dict[str, str] = {}
    names: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("i2ris_calib"):
            api.update({a.name: node.module for a in node.names})
        elif isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "__all__":
            names = list(ast.literal_eval(node.value))
    return api, names


#: public name -> module that defines it, and the public names (both from the stub)
_API, __all__ = _stub_names()
#: public functions made here (wrappers with argument checks): name -> (module, function)
_IO = {"load_synced": ("i2ris_calib.io.synced", "load_synced"),
       "load_config": ("i2ris_calib.io.config_io", "load_config")}  # fmt: skip

_FRAME_HINT = "a DataFrame in memory: make_dataset(axis, direction, df['time_s'], ...)"


def __dir__() -> list[str]:
    """The public names (``__all__``): not the face's private helpers."""
    return list(__all__)


def __getattr__(name: str):
    """The public ``name``, imported from its module on first use and kept here."""
    value = _load(name)
    globals()[name] = value  # later look-ups do not come back here
    return value


def _load(name: str):
    if name in _API:
        return getattr(_import_module(_API[name]), name)
    if name in _IO:
        mod, attr = _IO[name]
        obj = getattr(_import_module(mod), attr)
        v = _import_module("i2ris_calib._validate")
        if name == "load_synced":
            checked_fit_config = _import_module("i2ris_calib.fitting.pipeline").checked_fit_config
            checked_directions = _import_module("i2ris_calib.data.dataset").checked_directions

            def load_synced(path, axis, config=None, directions=None, columns=None):  # .pyi
                """The datasets ``i2ris-calib fit`` fits, as a list of ``Dataset``: on a
                synced CSV, the paper's split, one per motion direction with enough
                motion, ``+`` before ``-`` (``[0]`` is ``yaw+`` of a paper-like
                recording), or the one signed ``±`` dataset when the recording calls for
                it (the input crosses zero, excursions do not start at rest;
                ``config.signed`` / ``config.split`` force one), the same rule as the
                command line. Each holds the whole history (every sample, in time
                order), its loss mask and held-out cycles; ``fit(model, data)`` takes one.
                ``directions``: only these (``("-",)``); ``columns``: a lab file's column
                mapping (``ColumnsConfig``, docs/formats.md)."""
                func = "load_synced"
                v.check_path(func, "path", path, "a synced CSV", _FRAME_HINT)
                v.check_choice(func, "axis", axis, ("yaw", "pitch"))
                config = checked_fit_config(func, config)
                if directions is not None:
                    directions = checked_directions(func, directions)
                if columns is not None:
                    columns_config = _import_module("i2ris_calib.config").ColumnsConfig
                    v.check_instance(func, "columns", columns, columns_config)
                return obj([path], axis, config, directions, columns=columns)

            return load_synced

        def load_config(path=None):  # typed in __init__.pyi
            """The pipeline TOML at ``path`` (defaults when None) as a PipelineConfig."""
            if path is not None:
                v.check_path("load_config", "path", path, "a TOML config file (docs/config.md)")
            return obj(path)

        return load_config
    raise AttributeError(f"module 'i2ris_calib' has no attribute {name!r}")
