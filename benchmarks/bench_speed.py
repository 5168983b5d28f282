"""Speed benchmark: fit and diagnose on 50,000-sample recordings, one core (issue 20 item 7).

Run: ``NUMBA_NUM_THREADS=1 python benchmarks/bench_speed.py`` (``--repeats N``: timed
runs per figure, the median printed, default 3; ``--only fit|diagnose``; ``--cases``
a comma list of split,signed,coupled,piezo; ``--draws K``: K recordings per case, from
the case's own seed up; default 1).

Three recordings of 50,000 samples, each fitted by the default path (the model choice
of :func:`~i2ris_calib.fitting.pipeline.choose_model` and its kinds in fitting order,
each kind's time including nothing but its own fit: the kinds it nests are fitted
before and passed in, as ``fit`` does):

* ``split``: the paper's protocol (excursions from rest in both directions, holds at
  zero, EGPI truths as bench_model_stage part c; 100 Hz-like), the "+" direction
  dataset: GPI, EGPI, EGPI_C;
* ``signed``: a two-tendon axis driven through zero at 30 Hz, starting mid-loop
  (bench_two_tendon's draw): GPI and the two-tendon GPI over the signed input;
* ``coupled``: the pitch axis of a two-motor recording (bench_two_motor's simulator,
  30 Hz): GPI, the two-tendon GPI and the coupled two-tendon GPI;
* ``piezo``: a piezo-like actuator driven through zero at 200 Hz (bench_piezo's
  Bouc-Wen and elasto-slip generators, a 1 Hz sine, steps and holds, starting
  mid-loop): GPI, the two-tendon GPI and the one-loop kinds over the signed input.

``diagnose`` (default settings, ``diagnose_from_starts``: its starting fits on the
whole recording included) on each. Targets: every fit <= 5 s, every diagnose <= 15 s
(wall time, or this process's CPU time on a shared machine: the medians of both are
printed). Printed besides: each fit's RMSE and held-out RMSE (deg), to compare runs before and
after a change of the fitter.
"""

from __future__ import annotations

import argparse
import inspect
import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from i2ris_calib.commands.fit import recording_summary  # noqa: E402
from i2ris_calib.data.dataset import direction_datasets, input_bands  # noqa: E402
from i2ris_calib.diagnosis.config import DiagnosisConfig  # noqa: E402
from i2ris_calib.diagnosis.workflow import diagnose_from_starts  # noqa: E402
from i2ris_calib.fitting.config import FitConfig  # noqa: E402
from i2ris_calib.fitting.pipeline import choose_model, fit_dataset  # noqa: E402
from i2ris_calib.hysteresis.models import i2ris_egpi_model  # noqa: E402
from i2ris_calib.hysteresis.presets import (  # noqa: E402
    random_i2ris_egpi_params,
    random_two_tendon_params,
    through_zero_trajectory,
)
from i2ris_calib.hysteresis.registry import model_for_kind  # noqa: E402
from i2ris_calib.simulation import trajectory as tj  # noqa: E402
from i2ris_calib.simulation.piezo import bouc_wen_actuator, maxwell_slip_actuator  # noqa: E402
from i2ris_calib.simulation.presets import preset_config  # noqa: E402
from i2ris_calib.simulation.truth import whole_history_angle  # noqa: E402
from i2ris_calib.simulation.two_motor import simulate_two_motor  # noqa: E402

N = 50_000
FIT_TARGET_S = 5.0
DIAGNOSE_TARGET_S = 15.0


def split_case(n: int = N, seed: int = 11):
    """The "+" dataset of a paper-protocol recording of ``n`` samples (EGPI truths)."""
    cfg = preset_config(
        "exact_ci", seed=seed, datasets=("yaw+", "yaw-"), excursions=5,
        amplitude_counts=(6000.0, 6000.0), ramp_s=2.5, pause_s=0.5, hold_s=(0.3, 1.5),
    )  # fmt: skip
    t = np.linspace(0.0, tj.motion_duration_s(cfg), n, endpoint=False)
    enc = tj.session_inputs(cfg, t)[0].astype(float)
    rng = np.random.default_rng(seed)
    db = input_bands(enc).deadband
    models = {}
    for d in ("+", "-"):
        m = i2ris_egpi_model(deadband_counts=db, **random_i2ris_egpi_params(rng))
        models[d] = (m, m.values)
    y = whole_history_angle(enc, models, input_bands(enc).zero_band, t)
    theta = y + rng.normal(0.0, 0.1, y.size)
    return t, enc, theta, None, None


def signed_case(n: int = N, seed: int = 7):
    """A two-tendon axis driven through zero at 30 Hz, starting mid-loop."""
    rng = np.random.default_rng(seed)
    truth = random_two_tendon_params(rng)
    t, v, start = through_zero_trajectory(rng, n, 30.0)
    y = model_for_kind("agpi").with_values(truth)(v)[start:]
    return t[start:], v[start:], y + rng.normal(0.0, 0.25, y.size), None, None


def coupled_case(n: int = N, seed: int = 200):
    """The pitch axis of a two-motor recording (30 Hz), the yaw motor moving too."""
    rec = simulate_two_motor(seed, n, 30.0)
    return rec.t_s, rec.enc_pitch, rec.pitch_deg, rec.enc_yaw, rec.yaw_deg


def piezo_case(n: int = N, seed: int = 300):
    """A piezo-like actuator driven through zero at 200 Hz (bench_piezo's generators,
    none of the project's forms: the Bouc-Wen actuator for even seeds, the elasto-slip
    bank for odd ones): a 1 Hz sine of amplitude 120-150 (60 % of the samples), steps
    between random levels held 0.4-1.2 s (25 %), the sine again; noise U(0.03, 0.08)
    um; the recording starts mid-loop (after a 2.3 s burn-in)."""
    rng = np.random.default_rng(seed)
    burn = 460
    k = np.arange(n + burn)
    u = rng.uniform(120.0, 150.0) * np.sin(2.0 * np.pi * k / 200.0 + rng.uniform(0, 2 * np.pi))
    i, end = int(0.6 * k.size), int(0.85 * k.size)
    while i < end:
        hold = int(rng.uniform(0.4, 1.2) * 200.0)
        u[i : min(i + hold, end)] = rng.uniform(-150.0, 150.0)
        i += hold
    u = np.round(u, 2)
    d = rng.uniform(0.08, 0.12)
    if seed % 2 == 0:
        bg, frac = rng.uniform(0.01, 0.03), rng.uniform(0.4, 0.8)
        width = rng.uniform(0.08, 0.15) * d * 150.0
        y = bouc_wen_actuator(u, d, width * bg, frac * bg, (1.0 - frac) * bg)
    else:
        m = int(rng.integers(4, 9))
        r = np.sort(np.exp(rng.uniform(np.log(5.0), np.log(120.0), m)))
        y = maxwell_slip_actuator(u, d, rng.dirichlet(np.ones(m)) * rng.uniform(0.15, 0.35) * d, r)
    y = y[burn:] + rng.normal(0.0, rng.uniform(0.03, 0.08), n)
    return k[:n] / 200.0, u[burn:], y, None, None


CASES = {"split": split_case, "signed": signed_case, "coupled": coupled_case, "piezo": piezo_case}


def datasets_and_choice(case, config: FitConfig):
    """(the datasets the default fit fits, its model choice): as ``fit`` decides."""
    t, v, theta, v_other, theta_other = case
    kw = dict(enc_other=v_other, theta_other_deg=theta_other)
    whole = direction_datasets("pitch", t, v, theta, signed=True, **kw)
    recording, together = recording_summary(whole)
    choice = choose_model(recording, config, "all", together)
    if choice.signed:
        return whole, choice
    return direction_datasets("pitch", t, v, theta, directions=("+",), **kw), choice


def timed(f, repeats: int):
    """(median wall seconds, median CPU seconds of this process, the last result) of
    ``repeats`` calls of ``f`` (CPU time: what one idle core would take, about)."""
    wall, cpu, out = [], [], None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = f()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), float(np.median(cpu)), out


def bench_fit(name: str, d, choice, config: FitConfig, repeats: int) -> bool:
    ok, done = True, {}
    for kind in choice.kinds:
        dt, cpu, res = timed(lambda k=kind: fit_dataset(k, d, config, dict(done)), repeats)
        done[kind] = res
        good = min(dt, cpu) <= FIT_TARGET_S
        ok &= good
        print(
            f"fit       {name:8s} {d.name:8s} {kind:13s} {dt:6.2f} s (CPU {cpu:6.2f} s)  RMSE "
            f"{res.metrics.rmse_deg:.5f}  held-out {res.holdout_metrics.rmse_deg:.5f}  "
            f"nfev {res.nfev:4d}  {'ok' if good else 'SLOW'}",
            flush=True,
        )
    return ok


def bench_diagnose(name: str, d, config: FitConfig, repeats: int) -> bool:
    dt, cpu, auto = timed(lambda: diagnose_from_starts(d, DiagnosisConfig(), config), repeats)
    good = min(dt, cpu) <= DIAGNOSE_TARGET_S
    named = ", ".join(auto.diagnosis.named_effects) or "nothing"
    print(
        f"diagnose  {name:8s} {d.name:8s} from {auto.start:9s} {dt:6.2f} s (CPU {cpu:6.2f} s)  "
        f"names: {named}; "
        f"final held-out {auto.diagnosis.final.holdout_rmse_deg:.5f}  "
        f"{'ok' if good else 'SLOW'}",
        flush=True,
    )
    return good


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", choices=("fit", "diagnose"))
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument(
        "--draws", type=int, default=1,
        help="recordings per case: the case's own seed and the next ones (default 1)",
    )  # fmt: skip
    args = ap.parse_args()
    config = FitConfig()
    # compile the kernels (and warm the caches) on small recordings first
    for make in CASES.values():
        ds, choice = datasets_and_choice(make(3000), config)
        done = {}
        for k in choice.kinds:
            done[k] = fit_dataset(k, ds[0], config, done)
    fits_ok = diag_ok = True
    for name in args.cases.split(","):
        seed0 = inspect.signature(CASES[name]).parameters["seed"].default
        for seed in range(seed0, seed0 + max(args.draws, 1)):
            (d, *_), choice = datasets_and_choice(CASES[name](seed=seed), config)
            print(f"# {name} (seed {seed}): {choice.line}", flush=True)
            if args.only != "diagnose":
                fits_ok &= bench_fit(name, d, choice, config, args.repeats)
            if args.only != "fit":
                diag_ok &= bench_diagnose(name, d, config, args.repeats)
    if args.only != "diagnose":
        print(f"fit targets (each <= {FIT_TARGET_S:.0f} s):", "met" if fits_ok else "MISSED")
    if args.only != "fit":
        print(f"diagnose targets (each <= {DIAGNOSE_TARGET_S:.0f} s):",
              "met" if diag_ok else "MISSED")  # fmt: skip
    return 0 if (args.only == "diagnose" or fits_ok) and (args.only == "fit" or diag_ok) else 1


if __name__ == "__main__":
    raise SystemExit(main())
