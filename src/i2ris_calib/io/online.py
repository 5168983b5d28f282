"""Files of the online :class:`Compensator`: built from a fit.json, saved to and
loaded from the self-contained JSON a controller reads (docs/compensate.md, "Online
use"; schema :data:`~i2ris_calib.compensation.online.SCHEMA`)."""

from __future__ import annotations

import json
import warnings
from collections.abc import Sequence
from pathlib import Path

from i2ris_calib.compensation.online import OnlineInverse
from i2ris_calib.compensation.plan import ONLINE_KINDS, axis_plan, online_kind
from i2ris_calib.errors import CalibError
from i2ris_calib.io.atomic import write_json
from i2ris_calib.io.fit import read_fit_json
from i2ris_calib.io.fit_records import API_NAMES, dataset_record, fitted_dataset, load_model

__all__ = ["ONLINE_KINDS", "Compensator"]


class Compensator(OnlineInverse):
    """The online compensator: the file-free inverse
    (:class:`i2ris_calib.compensation.online.OnlineInverse`: built from models, its
    ``step``, ``advance``, ``state``, ``to_dict``) with its files: :meth:`from_fit`,
    :meth:`to_json`, :meth:`from_json`.

    Example (a control loop at 100 Hz)::

        c = Compensator.from_fit("fit/fit.json", dataset="yaw±")
        while running:
            cmd = c.step(target_yaw_deg=read_target(), dt_s=0.01)["yaw"]
            send_counts(int(cmd.counts))
    """

    @classmethod
    def from_fit(
        cls,
        path: str | Path | Sequence[str | Path],
        dataset: str | Sequence[str] | None = None,
        model: str | None = None,
        max_counts_per_s: float | None = None,
        start_counts: float | dict[str, float] = 0.0,
        history: dict[str, Sequence[float]] | None = None,
        dt_s: float = 0.01,
        model_file: str | Path | None = None,
    ) -> Compensator:
        """A compensator of the fitted model(s) in fit.json file(s) (one per axis).

        Parameters
        ----------
        path : path or sequence of paths
            fit.json written by ``fit`` (one per axis).
        dataset : str or sequence of str, optional
            ``yaw+``, ``yaw-``, ``yaw±``, ... per file; default: the signed dataset of the
            file when it has one, else its first dataset.
        model : str, optional
            ``gpi``, ``egpi``, ``egpi_c``, ``agpi``, ``agpi_coupled`` or ``diagnosed``
            (with ``model_file``; its time delay is inverted); default: the model fit.json
            recommends for the dataset (its ``decision``); when that one cannot be
            inverted online (no inverse, or ``agpi_coupled`` with one axis's fit: it
            reads the other motor's commands), the next of the decision's ranking, with a
            warning saying which and why.
        max_counts_per_s : float, optional
            Rate limit (counts/s; ``inf``: none); default: the fit's fastest input move
            (as ``compensate``).
        start_counts : float or dict
            Signed counts the motor(s) rest at (per axis with a dict; a coupled axis
            compensated alone: its other motor's too).
        history : dict, optional
            Axis -> signed counts already sent, oldest first, ``dt_s`` apart (a
            conditioning sweep, or the commands before): the model starts at rest at the
            first and is carried through the rest (as ``compensate --history``);
            replaces ``start_counts``.
        dt_s : float
            Interval of the ``history`` samples (s).
        model_file : path, optional
            final_model.json of ``--model diagnosed`` (checked against the fit).
        """
        paths = [path] if isinstance(path, (str, Path)) else list(path)
        names = _dataset_names(dataset, len(paths))
        mf = None if model_file is None else Path(model_file)
        models, limits, signs, rates = {}, {}, {}, {}
        for p, name in zip(paths, names, strict=True):
            p = Path(p)
            doc = read_fit_json(p)
            name = _dataset_name(doc, name)
            record = dataset_record(doc, name, p, API_NAMES)
            fit = fitted_dataset(record, p)
            kind, note = online_kind(fit, model, coupled_ok=len(paths) > 1)
            if note:
                warnings.warn(f"Compensator.from_fit: {note}", stacklevel=2)
            ax = name[:-1]
            if ax in models:
                raise CalibError(f"Compensator.from_fit: two fits of the {ax} axis")
            models[ax] = load_model(doc, record, kind, p, mf, API_NAMES)
            plan = axis_plan(fit, max_counts_per_s, 0.0, API_NAMES["rate"])
            limits[ax] = (plan.lo, plan.hi)
            signs[ax] = plan.sign
            rates[ax] = plan.rate.counts_per_s
        return cls(
            models,
            limits,
            signs=signs,
            max_counts_per_s=rates,
            start_counts=start_counts,
            history=history,
            dt_s=dt_s,
        )

    def to_json(self, path: str | Path) -> None:
        """Write :meth:`to_dict` (atomically) to ``path``."""
        write_json(path, self.to_dict())

    @classmethod
    def from_json(cls, path: str | Path) -> Compensator:
        """The compensator saved by :meth:`to_json` (its state included)."""
        p = Path(path)
        try:
            doc = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise CalibError(f"{p}: not a readable compensator JSON ({exc})") from None
        try:
            base = OnlineInverse.from_dict(doc)
        except CalibError as exc:
            raise CalibError(f"{p}: {exc}") from None
        return cls._from_axes(base._axes)


def _dataset_names(dataset, n_files: int) -> list:
    """One dataset name (or None) per fit.json: ``dataset`` as given, one None each."""
    names = [dataset] if isinstance(dataset, str) or dataset is None else list(dataset)
    if len(names) == 1 and n_files > 1:
        names = names * n_files if names[0] is None else names
    if len(names) != n_files:
        raise CalibError("Compensator.from_fit: give one dataset per fit.json (or none)")
    return names


def _dataset_name(doc: dict, name: str | None) -> str:
    """``name`` with ``+-`` read as ``±``; None: the fit's signed dataset when it has one,
    else its first."""
    if name is None:
        axis = str(doc.get("axis"))
        have = [str(d.get("name")) for d in doc.get("datasets", [])]
        name = f"{axis}±" if f"{axis}±" in have else (have[0] if have else f"{axis}+")
    return name.replace("+-", "±")
