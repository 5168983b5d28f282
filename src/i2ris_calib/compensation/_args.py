"""Argument checks of :func:`~i2ris_calib.compensation.inverse.compensate` (the public
entry): a misuse is a one-line CalibError naming the argument, before any work.

The data checks that the command line also meets (NaN in the target, times that do
not increase, ``lo < hi``, a rate limit without times) stay in ``inverse`` with
their messages; these are the ones only a Python caller can get wrong: a factory
instead of a model, a column or a DataFrame instead of an array, a scalar or None
instead of ``(lo, hi)``, a str instead of a number.
"""

from __future__ import annotations

import numpy as np

from i2ris_calib._validate import as_1d_float, as_real, check_model, describe, same_length
from i2ris_calib.errors import CalibError


def check_args(model, target_deg, t_s, v_limits, max_rate, quantum, v_initial, tol_deg) -> None:
    """CalibError naming the argument of ``compensate`` that is not what it must be."""
    func = "compensate"
    check_model(func, "model", model, usage="compensate(model, target_deg, t_s, v_limits=...)")
    target = as_1d_float(func, "target_deg", target_deg, finite=False)
    t = None if t_s is None else as_1d_float(func, "t_s", t_s, finite=False)
    same_length(func, target_deg=target, t_s=t)
    try:
        lims = np.asarray(v_limits, dtype=float)
    except (TypeError, ValueError):
        lims = None
    if lims is None or lims.shape != (2,) or isinstance(v_limits, str):
        raise CalibError(
            f"{func}: v_limits is {describe(v_limits)}; give (lo, hi), the input range the "
            "model may use, e.g. (0, 6000)"
        )
    as_real(func, "max_rate", max_rate, none_ok=True, finite=False)
    as_real(func, "quantum", quantum)
    as_real(func, "v_initial", v_initial, none_ok=True)
    as_real(func, "tol_deg", tol_deg, none_ok=True)
