"""The diagnosis and compensation sections, and the two-tendon models in every part,
from small synthetic data objects (formats of commands/diagnose.py, commands/compensate.py, fit.json)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from runfolder import tiny_png

from i2ris_calib.report import figures, tables
from i2ris_calib.report.build import (
    compensation_section,
    dataset_params,
    diagnosis_section,
    model_choice_verdicts,
    parameter_info,
)
from i2ris_calib.report.config import ReportConfig
from i2ris_calib.report.data import CompensationData, DiagnosisData, FitData
from i2ris_calib.report.document import Figure, MarkdownFragment, Table, Verdict
from i2ris_calib.report.render import png_size

CFG = ReportConfig(figure_dpi=40)
EXPERIMENT = "a slow and a fast ramp to the same level"


def _alt(effect, z, excluded=False, start=None):
    a = {
        "effect": effect,
        "holdout_rmse_deg": 0.2,
        "z": z,
        "p_value": 0.9,
        "excluded": excluded,
        "params": {"width_counts": 351.2},
        "experiment": EXPERIMENT,
        "effect_rms_deg": 1.07,
    }
    return a | ({"start": start} if start else {})


def diagnosis_record(named=True) -> dict:
    """A diagnosis.json as commands/diagnose.py writes it (the fields the report reads)."""
    steps = []
    if named:
        steps.append(
            {
                "effect": "time_delay",
                "meaning": "transport delay (tendon wave, controller or logging latency)",
                "params": {"tau_s": 0.1361},
                "holdout_rmse_before_deg": 0.737,
                "holdout_rmse_after_deg": 0.195,
                "delta_bic": -5520.4,
                "evidence": {"z": 33.2, "rel_improvement": 0.73, "p_value": 0.0},
                "alternatives": [_alt("creep", -0.4), _alt("backlash", 5.0, excluded=True)],
                "figures": {"before": "residual_00_start.png", "after": "residual_01_time_delay.png"},
            }
        )  # fmt: skip
    figs = ["residual_00_start.png"] + (["residual_01_time_delay.png"] if named else [])
    final = {"fit_rmse_deg": 0.196, "holdout_rmse_deg": 0.195 if named else 0.737, "bic": -4863.0,
             "n_free": 14}  # fmt: skip
    return {
        "dataset": "yaw±",
        "start": "auto",
        "start_model": "agpi",
        "reconciliation": "from agpi: time_delay" if named else "from agpi: nothing missing",
        "baseline": {"fit_rmse_deg": 1.204, "holdout_rmse_deg": 0.737, "bic": 662.0, "n_free": 13},
        "final": final,
        "named_effects": ["time_delay"] if named else [],
        "steps": steps,
        "not_excluded": [_alt("multi_stage_backlash", -1.3, start="agpi")],
        "paths": {
            "agpi": {
                "named_effects": ["time_delay"],
                "baseline": {"holdout_rmse_deg": 0.737},
                "final": {"holdout_rmse_deg": 0.195},
                "summary": "time_delay.",
            },
            "gpi": {
                "named_effects": ["time_delay"],
                "baseline": {"holdout_rmse_deg": 0.9},
                "final": {"holdout_rmse_deg": 0.3},
                "summary": "time_delay.",
            },
        },  # fmt: skip
        "figures": figs,
    }


def _diag_data(named=True, markdown=None) -> DiagnosisData:
    rec = diagnosis_record(named)
    images = {f: tiny_png(30 + 10 * i, 20) for i, f in enumerate(rec["figures"])}
    return DiagnosisData("yaw±", rec, markdown, images)


def _sub(section):
    (sub,) = section.subsections
    return sub


def test_diagnosis_opens_with_verdicts_then_before_after_figure():
    sec = _sub(diagnosis_section((_diag_data(),), CFG))
    assert sec.anchor == "diagnosis-yaw_signed"
    verdicts = [b for b in sec.blocks if isinstance(b, Verdict)]
    assert sec.blocks[: len(verdicts)] == tuple(verdicts)  # verdicts first
    assert verdicts[0].status == "ok"
    assert verdicts[0].text == (
        "yaw±: named time_delay (held-out RMSE 0.737 → 0.195 deg), starting from agpi."
    )
    assert verdicts[1].status == "warn" and "multi_stage_backlash" in verdicts[1].text
    assert any(v.text == "The agpi and gpi starts agree." for v in verdicts)
    fig = sec.blocks[len(verdicts)]
    assert isinstance(fig, Figure) and fig.name == "diagnose_yaw_signed_before_after"
    assert png_size(fig.png) == (520, 192)  # 13 x 4.8 in at 40 dpi
    assert "before (left, the starting model agpi)" in fig.caption


def test_named_effect_with_its_fitted_values_and_the_ties():
    sec = _sub(diagnosis_section((_diag_data(),), CFG))
    by_head = {b.header[1]: b for b in sec.blocks if isinstance(b, Table)}
    named = by_head["named effect"]
    assert named.rows == (
        (
            "1",
            "time_delay",
            "transport delay (tendon wave, controller or logging latency)",
            "tau_s = 0.136",
            "0.737 → 0.195",
            "33",
            "-5520",
        ),
    )
    ties = by_head["not excluded"]
    # the excluded backlash is not a tie; the step's creep and the final alternative are
    assert [(r[0], r[1]) for r in ties.rows] == [
        ("step 1 (vs time_delay)", "creep"),
        ("final model (agpi start)", "multi_stage_backlash"),
    ]
    assert ties.rows[0][2:5] == ("width_counts = 351", "1.1", "-0.4")
    assert all(r[5] == EXPERIMENT for r in ties.rows)
    paths = by_head["named"]
    assert [r[0] for r in paths.rows] == ["agpi (answer)", "gpi"]
    start_final = by_head["start"]
    assert dict((r[0], r[1:]) for r in start_final.rows)["free parameters"] == ("13", "14")


def test_nothing_named_is_said_and_the_one_figure_is_not_repeated():
    md = "# Model diagnosis\n\n![residual of the starting model](residual_00_start.png)\n"
    sec = _sub(diagnosis_section((_diag_data(named=False, markdown=md),), CFG))
    assert sec.blocks[0].text.startswith("yaw±: nothing missing (held-out RMSE 0.737 deg)")
    figs = [b for b in sec.blocks if isinstance(b, Figure)]
    assert figs == []  # diagnosis.md shows the start model's residual, once
    (frag,) = [b for b in sec.blocks if isinstance(b, MarkdownFragment)]
    assert list(frag.images) == ["residual_00_start.png"]
    # the verdict leads; diagnosis.md (which repeats the verdict and path tables) is
    # the evidence, folded behind <details> (issue 33: 40 % of the report's text)
    assert frag.summary.startswith("The evidence: the diagnosis stage's full account")
    # without diagnosis.md the one residual figure is drawn alone
    sec = _sub(diagnosis_section((_diag_data(named=False),), CFG))
    (fig,) = [b for b in sec.blocks if isinstance(b, Figure) and "before_after" in b.name]
    assert png_size(fig.png) == (280, 200) and "nothing was added" in fig.caption


def test_diagnosis_degrades_without_optional_fields():
    dd = DiagnosisData("pitch-", {"named_effects": ["creep"]})
    sec = _sub(diagnosis_section((dd,), CFG))
    assert sec.blocks[0] == Verdict("named creep.", "ok")


# ---------------------------------------------------------------- compensation


def compensation_data(two_axes=True) -> CompensationData:
    """commands.csv (3 entry rows, then 20 target rows) and compensate.json."""
    n_entry, n = 3, 20
    t = np.r_[-0.1 * np.arange(n_entry, 0, -1), 0.1 * np.arange(n)]
    yaw = np.r_[[100, 200, 300], 300 + 50 * np.arange(n)].astype(int)
    flags = ["yaw:entry;pitch:entry"] * n_entry + [""] * n
    flags[n_entry + 4] = "yaw:above_range;pitch:rate_limited"
    flags[n_entry + 5] = "yaw:above_range"
    cmd = pd.DataFrame({"time_s": t, "enc_yaw": yaw, "enc_pitch": -yaw,
                        "predicted_yaw_deg": 0.01 * yaw, "predicted_pitch_deg": -0.01 * yaw,
                        "reachable": 1, "flags": flags})  # fmt: skip
    target = pd.DataFrame({"time_s": t[n_entry:], "yaw_deg": 0.01 * yaw[n_entry:] + 0.1,
                           "pitch_deg": -0.01 * yaw[n_entry:]})  # fmt: skip
    ranking = [
        {"model": k, "predicted_rmse_deg": 0.1 * (i + 1), "holdout_rmse_deg": 0.2,
         "score_deg": 0.3 * (i + 1), "output_steps": i, "continuous": i < 2, "rank": i + 1,
         "chosen": i == 0}
        for i, k in enumerate(("agpi_coupled", "agpi", "gpi"))
    ]  # fmt: skip

    def axis(name, flags_, rate_seen):
        return {
            "dataset": name, "model": "agpi_coupled", "model_choice": "ranking",
            "ranking": ranking, "input_range_counts": [-2000.0, 2000.0],
            "max_counts_per_s": 1000.0,
            "max_counts_per_s_source": "fit.json max_input_rate_counts_per_s",
            "max_command_rate_per_s": rate_seen, "start_counts": 0.0,
            "start_counts_source": "default (rest at 0)", "n_samples": n, "rmse_deg": 0.1,
            "max_abs_err_deg": 0.1, "n_unreachable": sum(flags_.values()), "flags": flags_,
            "n_entry": n_entry, "entry_s": 0.3, "spikes_left": 0, "warnings": [],
        }  # fmt: skip

    zero = dict.fromkeys(("above_range", "below_range", "within_delay", "rate_limited",
                          "output_step", "spike_removed"), 0)  # fmt: skip
    axes = {"yaw": axis("yaw±", zero | {"above_range": 2}, 1000.0)}
    if two_axes:
        axes["pitch"] = axis("pitch±", zero | {"rate_limited": 1}, 1500.0)
    return CompensationData(doc={"axes": axes}, commands=cmd, target=target)


def test_compensation_verdicts_figure_flags_and_ranking():
    sec = compensation_section(compensation_data(), CFG)
    verdicts = [b for b in sec.blocks if isinstance(b, Verdict)]
    assert sec.blocks[: len(verdicts)] == tuple(verdicts)
    texts = {v.text: v.status for v in verdicts}
    main = (
        "yaw±: two-tendon GPI + hysteretic coupling to the other motor (best of the "
        "ranking): predicted RMSE 0.10 deg, max 0.10 deg; 2 of 20 target samples unreachable."
    )
    assert texts[main] == "warn"
    rate_ok = [t for t in texts if t.startswith("yaw±: rate limit 1000 counts/s")]
    assert rate_ok and texts[rate_ok[0]] == "ok"
    over = [t for t in texts if t.startswith("pitch±: rate limit")]
    assert over[0].endswith("reach 1500 counts/s (above it).") and texts[over[0]] == "warn"
    assert any(t.startswith("yaw±: entry ramp of 3 samples") for t in texts)
    (fig,) = [b for b in sec.blocks if isinstance(b, Figure)]
    assert fig.name == "compensation" and png_size(fig.png) == (520, 320)  # 13 x 8 in
    flag_t = next(b for b in sec.blocks if isinstance(b, Table) and b.header[0] == "flag")
    counts = {r[0]: r[2:] for r in flag_t.rows}
    assert counts["above_range"] == ("2", "0") and counts["rate_limited"] == ("0", "1")
    assert counts["entry"] == ("3", "3")
    rank = next(b for b in sec.blocks if isinstance(b, Table) and "rank" in b.header)
    assert len(rank.rows) <= 10
    assert rank.rows[0][:3] == (
        "yaw±",
        "1",
        "two-tendon GPI + hysteretic coupling to the other motor (chosen)",
    )


def test_conditioning_sweep_is_said_counted_and_not_called_tracking():
    comp = compensation_data()
    n_cond = 2
    cmd = comp.commands
    head = cmd.iloc[:n_cond].copy()
    head["time_s"] = [-0.5, -0.4]
    head["flags"] = "yaw:conditioning;pitch:conditioning"
    comp = CompensationData(
        doc=comp.doc, commands=pd.concat([head, cmd], ignore_index=True), target=comp.target
    )
    reason = "the fit's recording started mid-loop (initial_state estimated)"
    for a in comp.doc["axes"].values():
        a.update(n_conditioning=n_cond, conditioning_s=0.2, start_state_reason=reason)
    sec = compensation_section(comp, CFG)
    texts = [b.text for b in sec.blocks if isinstance(b, Verdict)]
    assert (
        f"yaw±: conditioning sweep of 2 samples (0.2 s) over the fitted range first: {reason}."
        in texts
    )
    flag_t = next(b for b in sec.blocks if isinstance(b, Table) and b.header[0] == "flag")
    counts = {r[0]: r[1:] for r in flag_t.rows}
    assert counts["conditioning"][1:] == ("2", "2") and "not tracking" in counts["conditioning"][0]
    # the target is aligned to the last rows: the sweep rows get none
    target = figures.aligned_target(comp.commands, comp.target, "yaw")
    assert np.isnan(target[: n_cond + 3]).all() and np.isfinite(target[n_cond + 3 :]).all()


def test_flags_are_counted_from_the_csv_when_the_json_has_none():
    comp = compensation_data()
    for a in comp.doc["axes"].values():
        del a["flags"]
    sec = compensation_section(comp, CFG)
    flag_t = next(b for b in sec.blocks if isinstance(b, Table) and b.header[0] == "flag")
    counts = {r[0]: r[2:] for r in flag_t.rows}
    assert counts["above_range"] == ("2", "0") and counts["rate_limited"] == ("0", "1")


def test_axis_flags_and_target_alignment():
    comp = compensation_data()
    yaw = figures.axis_flags(comp.commands["flags"], "yaw", True)
    assert yaw[0] == {"entry"} and yaw[7] == {"above_range"} and yaw[10] == set()
    one = figures.axis_flags(pd.Series(["entry", np.nan, "output_step;rate_limited"]), "yaw", False)
    assert one == [{"entry"}, set(), {"output_step", "rate_limited"}]
    tgt = figures.aligned_target(comp.commands, comp.target, "yaw")
    assert np.isnan(tgt[:3]).all() and np.allclose(tgt[3:], comp.target["yaw_deg"])


# ---------------------------------------------------------------- two-tendon models


def _agpi_coupled_record() -> dict:
    names = ["theta0"] + [
        f"{b}{g}"
        for g in ("_p", "_n", "_cp", "_cn")
        for b in ("a1", "a2", "a3", "a4", "lam", "sigma", "r1", "rn")
        + (("sign",) if g in ("_cp", "_cn") else ())
    ]
    params = {n: 0.5 + i for i, n in enumerate(names)}
    fixed = {n for n in names if n[:2] in ("a2", "la", "si") and not n.startswith("sigma")}
    stderr = {n: (0.0 if n in fixed else 0.1) for n in names}
    return {"params": params, "stderr": stderr, "free": [n for n in names if n not in fixed],
            "units": {n: "deg" for n in names}, "converged": True}  # fmt: skip


def test_many_parameter_model_is_grouped_per_tendon_and_coupling():
    d = {"name": "pitch±", "direction": "±", "models": {"agpi_coupled": _agpi_coupled_record(),
                                                        "gpi": {"params": {"a1": 0.01}}}}  # fmt: skip
    grouped, flat, info_t = dataset_params(d, parameter_info())
    assert len(d["models"]["agpi_coupled"]["params"]) == 35
    assert grouped.header == (
        "parameter",
        "unit",
        "whole axis",
        "tendon + (positive input)",
        "tendon − (|negative input|)",
        "coupling: other motor +",
        "coupling: other motor −",
        "meaning",
    )
    assert [r[0] for r in grouped.rows] == [
        "theta0", "a1", "a2", "a3", "a4", "lam", "sigma", "r1", "rn", "sign",
    ]  # fmt: skip
    rows = {r[0]: r for r in grouped.rows}
    assert rows["theta0"][2:4] == ("0.50 ± 0.10", "—")
    assert rows["a1"][3] == "1.50 ± 0.10" and rows["a1"][5] == "17.50 ± 0.10"
    assert rows["a2"][3] == "2.5 (fixed)"
    assert rows["sign"][3:5] == ("—", "—")  # no sign on the tendons
    assert rows["a1"][-1] == "loading envelope slope"  # the group prefix is dropped
    assert flat.header[2] == "GPI (value ± stderr)" and "agpi" not in " ".join(flat.header)
    assert info_t.header[0] == "model"


def test_model_choice_line_per_axis_and_signed_curves_drawn():
    fit = {"model_choice": {"input": "signed", "kinds": ["gpi", "agpi"], "line": "model: X"}}
    old = {"datasets": []}
    got = model_choice_verdicts((FitData("pitch", fit), FitData("yaw", old)))
    assert got == [Verdict("pitch: model: X", "info")]
    pred = pd.DataFrame({"gpi_deg": [1.0, 2.0], "egpi_deg": [np.nan, np.nan],
                         "agpi_deg": [1.0, 2.0], "agpi_coupled_deg": [1.0, 2.0]})  # fmt: skip
    assert [c for c, _, _ in figures.drawn_models(pred)] == [
        "gpi_deg",
        "agpi_deg",
        "agpi_coupled_deg",
    ]
    assert tables.param_group("rn_cp") == ("rn", "_cp")
    assert tables.param_group("theta0") == ("theta0", None)
