"""``i2ris-calib paper-sim``: the paper's Section 3.1 simulation -> CSV, PNG figures, JSON.

Outputs (docs/models.md): ``paper_sim.csv`` (t, v, z1, z2, z), ``fig3c.png`` (z1 vs v),
``fig3d.png`` (z2 vs v), ``fig4.png`` (EGPI z vs v with the flag points and the dead
zones S1-S4 of the last full cycle), ``paper_sim.json`` (parameters, dead zones found
per branch, provenance).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from i2ris_calib.hysteresis.paper import (
    PAPER_SIM_RATE_HZ,
    PAPER_SIM_VALUES,
    dead_zones,
    run_paper_sim,
)
from i2ris_calib.io.atomic import atomic_path, write_csv, write_json
from i2ris_calib.io.outputs import output_dir
from i2ris_calib.io.provenance import provenance

#: The files ``paper-sim`` writes in its output folder.
OUTPUTS = ("paper_sim.csv", "paper_sim.json", "fig3c.png", "fig3d.png", "fig4.png")


def _figure(path: Path, v, y, title: str, ylabel: str, flags=None, zones=()) -> None:
    fig = Figure(figsize=(6.0, 4.5), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.plot(v, y, lw=0.8, color="tab:blue")
    if flags:
        for name, val, style in flags:
            ax.axvline(val, ls=style, color="tab:red", lw=1.0, label=f"{name} = {val:g}")
        ax.legend(loc="upper left", fontsize=8)
    lo, hi = ax.get_ylim()
    for label, z in zones:
        colour = "tab:green" if z.rising else "tab:orange"
        ax.axvspan(min(z.v_start, z.v_end), max(z.v_start, z.v_end), color=colour, alpha=0.12)
        where = (lo, "bottom") if z.rising else (hi, "top")
        ax.annotate(
            label + (" (rising)" if z.rising else " (falling)"),
            ((z.v_start + z.v_end) / 2, where[0]),
            ha="center",
            va=where[1],
            fontsize=8,
            color=colour,
        )
    ax.set_xlabel("input v")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)


def write_paper_sim(out: str | Path) -> dict:
    """Command body of ``paper-sim``: simulate, write CSV, figures and JSON into ``out``."""
    with output_dir(out, "paper-sim", (), OUTPUTS) as tmp:
        return _write_paper_sim(tmp)


def _write_paper_sim(out: Path) -> dict:
    sim = run_paper_sim()
    write_csv(
        out / "paper_sim.csv",
        pd.DataFrame({"t": sim.t, "v": sim.v, "z1": sim.z1, "z2": sim.z2, "z": sim.z}),
    )
    found = {
        name: dead_zones(sim.v, y) for name, y in (("z1", sim.z1), ("z2", sim.z2), ("z", sim.z))
    }
    last_rise = max(z.branch for z in found["z"] if z.rising)
    last_fall = max(z.branch for z in found["z"] if not z.rising)
    labelled = [z for z in found["z"] if z.branch in (last_rise, last_fall)]
    labels = sorted(
        labelled, key=lambda z: (not z.rising, -z.v_start if not z.rising else z.v_start)
    )
    zones = list(zip(("S1", "S2", "S3", "S4"), labels, strict=False))
    vf = PAPER_SIM_VALUES
    flags = [("v_f1", vf["vf_rise1"], "--"), ("v_f2", vf["vf_fall1"], ":")]
    _figure(out / "fig3c.png", sim.v, sim.z1, "Fig 3(c): GPI output z1", "z1")
    _figure(out / "fig3d.png", sim.v, sim.z2, "Fig 3(d): GPI output z2", "z2")
    _figure(
        out / "fig4.png",
        sim.v,
        sim.z,
        "Fig 4: EGPI output z (switching at v_f1, v_f2)",
        "z",
        flags,
        zones,
    )
    summary = {
        "schema": "i2ris-calib.paper-sim/1",
        "rate_hz": PAPER_SIM_RATE_HZ,
        "n_samples": int(sim.t.size),
        "params": PAPER_SIM_VALUES,
        "dead_zones": {
            name: [
                {"branch": z.branch, "rising": z.rising, "v_start": z.v_start, "v_end": z.v_end}
                for z in zones_
            ]
            for name, zones_ in found.items()
        },
        "provenance": provenance([], None),
    }
    write_json(out / "paper_sim.json", summary)
    return summary
