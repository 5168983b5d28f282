"""Online Compensator speed and exactness (issue 21 item 5): median microseconds per
``step()`` on one core, the largest difference between its commands and the batch
``compensate()``'s on the same target, and the batch time for 1e6 samples, per kind.

    NUMBA_NUM_THREADS=1 python benchmarks/bench_compensator_step.py [--kinds gpi egpi ...]

Model: the paper-like yaw+ preset (agpi: a two-tendon preset; agpi_coupled: that preset
on both axes with a hysteretic coupling to the other motor, both axes compensated by one
``step()`` call, solved jointly; egpi+delay: the EGPI with a 0.15 s time delay, the
step given the target 0.15 s ahead), whole counts, rate limit 5000 counts/s, a smooth
100 Hz target (15 + 8 sin(0.7 t) + 3 sin(2.1 t) deg; the two-tendon kinds: without the
15 deg offset; agpi_coupled pitch: 6 cos(0.9 t) - 1 deg). Online vs batch:
``compensate(..., v_initial=0, entry=False, repair_spikes=False)`` on the steps' samples
(agpi_coupled: each axis given the other motor's commands the online step sent). Batch:
``compensate(..., v_initial=0)`` with the defaults (entry ramp, spike repair) on 1e6
samples (agpi_coupled: one axis given the other motor's 1e6 commands), wall-clock and
the process's CPU time (the one-core figure on a shared machine). Targets: <= 20 us per
step, <= 5 s per 1e6 batch samples.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from i2ris_calib.compensation import compensate
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.hysteresis.effects import add_effect
from i2ris_calib.hysteresis.presets import gpi_values, paper_like_params
from i2ris_calib.hysteresis.registry import model_for_kind
from i2ris_calib.io.online import Compensator

AGPI = dict(
    theta0=0.4, a1_p=0.008, a3_p=0.0072, a4_p=-1.2, lam_p=0.06, sigma_p=0.25, r1_p=0.3,
    rn_p=3.5, a1_n=0.0065, a3_n=0.006, a4_n=-0.8, lam_n=0.06, sigma_n=0.2, r1_n=0.4, rn_n=3.0,
)  # fmt: skip
COUPLING = dict(a1_cp=0.0009, a3_cp=0.0008, a4_cp=-0.3, lam_cp=0.06, sigma_cp=0.2, r1_cp=0.3,
                rn_cp=3.0, sign_cp=1.0, a1_cn=0.0007, a3_cn=0.0006, a4_cn=-0.2, lam_cn=0.06,
                sigma_cn=0.2, r1_cn=0.4, rn_cn=3.0, sign_cn=-1.0)  # fmt: skip
KINDS = ("gpi", "egpi", "egpi_c", "agpi", "agpi_coupled", "egpi+delay")
RATE = 5000.0
TAU = 0.15


def setup(kind: str, n: int):
    """(models {axis: model}, v_limits {axis: ...}, targets {axis: (n,)}, t (n,))."""
    t = np.arange(n) * 0.01
    wave = 8 * np.sin(0.7 * t) + 3 * np.sin(2.1 * t)
    lim2 = (-4000.0, 4000.0)
    if kind == "agpi":
        return {"yaw": model_for_kind("agpi", **AGPI)}, {"yaw": lim2}, {"yaw": wave}, t
    if kind == "agpi_coupled":
        models = {
            "yaw": model_for_kind("agpi_coupled", **AGPI, **COUPLING),
            "pitch": model_for_kind("agpi_coupled", **(AGPI | COUPLING | {"theta0": -0.3})),
        }
        return models, {"yaw": lim2, "pitch": lim2}, {
            "yaw": wave, "pitch": 6 * np.cos(0.9 * t) - 1.0}, t  # fmt: skip
    base = kind.split("+")[0]
    pp = paper_like_params("yaw+")
    model = model_from_params(base, gpi_values(pp) if base == "gpi" else pp, 30, 2.0)
    if kind.endswith("+delay"):
        model = add_effect(model, "time_delay", {"tau_s": TAU})
    return {"yaw": model}, {"yaw": (0.0, 6000.0)}, {"yaw": 15 + wave}, t


def online_goals(kind, targets, t):
    """What the controller passes to step(): the target, or the target tau ahead."""
    if kind.endswith("+delay"):
        return {a: np.interp(t + TAU, t, x) for a, x in targets.items()}
    return targets


def time_steps(kind, n):
    models, lim, targets, t = setup(kind, n)
    goals = online_goals(kind, targets, t)
    c = Compensator(models, lim, max_counts_per_s=RATE)
    ya, pa = goals.get("yaw"), goals.get("pitch")
    for k in range(100):  # compile, warm
        c.step(float(ya[k]), None if pa is None else float(pa[k]), dt_s=0.01)
    c.reset()
    yl = ya.tolist()
    pl = [None] * n if pa is None else pa.tolist()
    per = np.empty(n)
    cmds = {a: np.empty(n) for a in models}
    clock = time.perf_counter
    for k in range(n):
        t0 = clock()
        out = c.step(yl[k], pl[k], 0.01)
        per[k] = clock() - t0
        for a, cmd in out.items():
            cmds[a][k] = cmd.counts
    return per, cmds


def batch_difference(kind, cmds, n):
    """Largest |online - batch| command (counts) over the axes."""
    models, lim, targets, t = setup(kind, n)
    worst = 0.0
    for axis, model in models.items():
        other = {"yaw": "pitch", "pitch": "yaw"}[axis]
        kw = {}
        if kind == "agpi_coupled":
            kw = dict(v_other=cmds[other], v_other_initial=0.0)
        res = compensate(model, targets[axis], t, v_limits=lim[axis], max_rate=RATE,
                         v_initial=0.0, entry=False, repair_spikes=False, **kw)  # fmt: skip
        worst = max(worst, float(np.max(np.abs(res.commands - cmds[axis]))))
    return worst


def time_batch(kind, n):
    models, lim, targets, t = setup(kind, n)
    model = models["yaw"]
    kw = {}
    if kind == "agpi_coupled":
        kw = dict(v_other=np.rint(2500 * np.sin(0.9 * t)), v_other_initial=0.0)
    small = {k: v[:1000] for k, v in kw.items() if k == "v_other"} | (
        {"v_other_initial": 0.0} if kw else {})  # fmt: skip
    compensate(model, targets["yaw"][:1000], t[:1000], v_limits=lim["yaw"], max_rate=RATE,
               v_initial=0.0, **small)  # fmt: skip
    t0, c0 = time.perf_counter(), time.process_time()
    compensate(model, targets["yaw"], t, v_limits=lim["yaw"], max_rate=RATE, v_initial=0.0, **kw)
    return time.perf_counter() - t0, time.process_time() - c0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--batch", type=int, default=1_000_000)
    args = ap.parse_args()
    ok = True
    for kind in args.kinds:
        per, cmds = time_steps(kind, args.steps)
        med = 1e6 * float(np.median(per))
        diff = batch_difference(kind, cmds, args.steps)
        batch, cpu = time_batch(kind, args.batch)
        axes = "both axes" if len(cmds) == 2 else "one axis"
        print(
            f"{kind:12s} step() ({axes}): median {med:6.2f} us (p99 "
            f"{1e6 * np.percentile(per, 99):6.2f} us, {'PASS' if med <= 20 else 'FAIL'} <= 20); "
            f"online vs batch max |diff| {diff:.1e} counts over {args.steps} steps "
            f"({'PASS' if diff <= 1e-9 else 'FAIL'} <= 1e-9); batch {args.batch:.0e} samples: "
            f"{batch:5.2f} s wall, {cpu:5.2f} s CPU ({'PASS' if cpu <= 5 else 'FAIL'} <= 5 on "
            "one core)",
            flush=True,
        )
        ok &= med <= 20 and diff <= 1e-9 and cpu <= 5
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
