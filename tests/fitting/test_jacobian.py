"""The models' exact Jacobians (used by the fitter instead of finite differences)."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.fitting.fit import _analytic_jacobian
from i2ris_calib.hysteresis.models import (
    ContinuousEGPIModel,
    continuous_egpi_model,
    gpi_model,
    i2ris_egpi_model,
)
from i2ris_calib.hysteresis.presets import loading_trajectory, random_i2ris_egpi_params


def _models(seed):
    p = random_i2ris_egpi_params(np.random.default_rng(seed))
    gpi = gpi_model(**{k: x for k, x in p.items() if k in gpi_model().names})
    return gpi, i2ris_egpi_model(**p), continuous_egpi_model(**p)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_jacobian_equals_central_differences(seed):
    """Every column (but the profiled v_f) equals a central difference of the output to
    1e-6 of its largest entry: the output is piecewise linear in these parameters, so a
    small step sees the exact slope except at rare ties of two boundaries."""
    _, v = loading_trajectory(np.random.default_rng(10 + seed), n_cycles=5, n_samples=3000)
    v = np.round(v)  # encoder counts: holds and repeated values
    for m in _models(seed):
        x = m.values
        jac = m.jacobian(v, x)
        assert jac.shape == (v.size, x.size)
        for j, name in enumerate(m.names):
            if name == "v_f":
                assert np.all(jac[:, j] == 0.0)
                continue
            h = 1e-9 if name in ("a1", "a3", "a5") else 1e-7 * max(1.0, abs(x[j]))
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            fd = (m.evaluate(v, xp) - m.evaluate(v, xm)) / (2 * h)
            scale = np.max(np.abs(fd))
            assert scale > 0, (m.name, name)
            np.testing.assert_allclose(jac[:, j], fd, atol=1e-6 * scale, err_msg=f"{m.name} {name}")


def test_subclass_overriding_evaluate_falls_back_to_finite_differences():
    class Shifted(ContinuousEGPIModel):
        def evaluate(self, signals, values):
            return super().evaluate(signals, values) + 1.0

    base = continuous_egpi_model()
    shifted = Shifted("shifted", base.parameters, n=base.n)
    assert _analytic_jacobian(base) is not None
    assert _analytic_jacobian(shifted) is None


@pytest.mark.parametrize("seed", [3, 4])
def test_flag_point_families_give_the_output_for_every_flag_point(seed):
    """The EGPI's flag point only switches between two outputs: the fitter's profile
    over v_f uses them, and must see exactly (bit for bit) what evaluate gives."""
    _, v = loading_trajectory(np.random.default_rng(seed), n_cycles=5, n_samples=3000)
    v = np.round(v)
    m = i2ris_egpi_model(**random_i2ris_egpi_params(np.random.default_rng(seed)))
    y1, y2, unloading = m.flag_point_families(v, m.values)
    assert np.any(y1 != y2)
    x = m.values
    for v_f in np.linspace(v.min(), v.max(), 25):
        x[-1] = v_f
        assert np.array_equal(np.where(unloading & (v <= v_f), y2, y1), m.evaluate(v, x))
    assert _analytic_jacobian(continuous_egpi_model(), "flag_point_families") is None
