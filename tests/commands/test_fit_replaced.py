"""A lower cost of a stored fit's model found by a later stage replaces it (issue 31):
the fit rerun from it through the fit stage's own code, fit.json and predictions.csv
written anew with a ``replaced`` record, read by compensate and the report; no lower
cost: fit.json is not touched.

Known truth: a fit.json whose GPI values are perturbed (a worse point of the same
model on the same data) and the unperturbed fit's values as the diagnosis's refit.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.commands.diagnose import diagnosis_dataset, replace_stored_fit
from i2ris_calib.commands.fit import stored_fit_record, stored_model
from i2ris_calib.config import PipelineConfig
from i2ris_calib.diagnosis.results import BaseRefit
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.pipeline import dataset_cost
from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import paper_like_params
from i2ris_calib.io.fit import read_fit_json
from i2ris_calib.io.provenance import file_sha256
from i2ris_calib.report.build import replaced_fit_verdicts
from i2ris_calib.report.data import FitData

FOUND_BY = "refit from creep's values"


def _synced(path: Path, seed: int = 5) -> None:
    """One yaw+ recording (pitch at rest): the paper-like EGPI over 4 loading cycles,
    noise 0.05 deg."""
    rng = np.random.default_rng(seed)
    n = 1200
    t = np.linspace(0.0, 24.0, n)
    amp = np.array([900.0, 1400.0, 1100.0, 1500.0])
    phase = (t / 6.0) % 1.0
    v = amp[np.minimum((t // 6.0).astype(int), 3)] * np.sin(np.pi * phase) ** 2
    model = i2ris_egpi_model(deadband_counts=2.0)
    theta = model.evaluate_dict(v, paper_like_params("yaw+"))
    theta = theta + rng.normal(0.0, 0.05, n)
    pd.DataFrame(
        {
            "time_s": t,
            "enc_yaw": v,
            "enc_pitch": 0.0,
            "yaw_deg": theta,
            "pitch_deg": rng.normal(0.0, 0.05, n),
            "status": "measured",
            "frame": np.arange(n),
        }
    ).to_csv(path, index=False)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """(synced CSV, the fit folder of `fit --model gpi`)."""
    root = tmp_path_factory.mktemp("replaced")
    csv = root / "synced.csv"
    _synced(csv)
    out = root / "fit"
    assert main(["fit", str(csv), "--axis", "yaw", "--model", "gpi", "--out", str(out)]) == 0
    return csv, out


def _perturbed(fitted, tmp_path) -> Path:
    """A copy of the fit folder whose yaw+ GPI has a1 x 1.3 (a worse point)."""
    _, out = fitted
    copy = tmp_path / "fit"
    shutil.copytree(out, copy)
    doc = json.loads((copy / "fit.json").read_text())
    for d in doc["datasets"]:
        d["models"]["gpi"]["params"]["a1"] *= 1.3
    doc["models"] = doc["datasets"][0]["models"]
    (copy / "fit.json").write_text(json.dumps(doc, indent=2) + "\n")
    return copy / "fit.json"


def _auto(model) -> SimpleNamespace:
    """The part of a diagnosis the replacement reads: the gpi path's refits of its base."""
    return SimpleNamespace(
        paths={"gpi": SimpleNamespace(base_refits=(BaseRefit(model, FOUND_BY),))}
    )


def _good_model(fitted, dset):
    _, out = fitted
    doc = read_fit_json(out / "fit.json")
    return stored_model(doc, doc["datasets"][0], "gpi", out / "fit.json")


def test_a_lower_cost_replaces_the_stored_fit_with_its_record(fitted, tmp_path):
    csv, _ = fitted
    cfg = PipelineConfig()
    path = _perturbed(fitted, tmp_path)
    before_sha = file_sha256(path)
    before = read_fit_json(path)
    dset = diagnosis_dataset(csv, "yaw", "+", cfg.fit)
    stored = stored_fit_record(path, dset, cfg)
    worse, state = stored_model(*stored, "gpi", path)
    good, _ = _good_model(fitted, dset)
    worse_cost = dataset_cost(worse, dset, cfg.fit, state)
    good_cost = dataset_cost(good, dset, cfg.fit, state)
    assert good_cost < 0.5 * worse_cost

    changes = replace_stored_fit(path, stored, dset, _auto(good), cfg)

    assert [(c["dataset"], c["kind"]) for c in changes] == [("yaw+", "gpi")]
    doc = read_fit_json(path)  # still a complete fit.json
    rec = doc["datasets"][0]["models"]["gpi"]
    r = rec["replaced"]
    assert r["previous_cost"] == pytest.approx(worse_cost, rel=1e-9)
    assert r["cost"] <= good_cost * (1 + 1e-6)
    assert r["cost"] == pytest.approx(rec["certificate"]["best_cost"], rel=1e-9)
    assert r["stage"] == "diagnose" and r["found_by"] == f"diagnose's {FOUND_BY}"
    assert r["previous_sha256"] == before_sha
    assert r["previous_params"] == before["datasets"][0]["models"]["gpi"]["params"]
    assert r["text"] == (
        f"fit.json's yaw+ gpi replaced: cost {worse_cost:.4g} -> {r['cost']:.4g} "
        f"(found by diagnose's {FOUND_BY})"
    )
    assert changes[0]["text"] == r["text"]
    # the certificate says so; the decision and the other records are the rerun's
    assert rec["certificate"]["replaced"] == r["text"]
    assert rec["certificate"]["text"].endswith(f"rerun: {r['text']}")
    assert doc["decision"]["model"] == "gpi" and doc["models"]["gpi"]["replaced"] == r
    for name, x in ((p.name, p.value) for p in good.parameters):
        assert rec["params"][name] == pytest.approx(x, rel=1e-3, abs=1e-6)
    # predictions.csv is the new fit's
    pred = pd.read_csv(path.parent / "predictions.csv")
    new_model, new_state = stored_model(doc, doc["datasets"][0], "gpi", path)
    assert dataset_cost(new_model, dset, cfg.fit, new_state) == pytest.approx(r["cost"], rel=1e-9)
    y = new_model.evaluate(dset.signals, np.array([p.value for p in new_model.parameters]))
    np.testing.assert_allclose(pred["gpi_deg"].to_numpy(), y, rtol=1e-8, atol=1e-8)
    # the report states it
    verdicts = replaced_fit_verdicts((FitData("yaw", doc),))
    assert [v.text for v in verdicts] == [f"yaw: {r['text']}"]
    assert not [p for p in path.parent.iterdir() if ".tmp-" in p.name]


def test_compensate_inverts_the_replaced_fit_and_says_so(fitted, tmp_path):
    from i2ris_calib.commands.compensate import compensate_files

    csv, _ = fitted
    cfg = PipelineConfig()
    path = _perturbed(fitted, tmp_path)
    dset = diagnosis_dataset(csv, "yaw", "+", cfg.fit)
    stored = stored_fit_record(path, dset, cfg)
    good, _ = _good_model(fitted, dset)
    replace_stored_fit(path, stored, dset, _auto(good), cfg)
    target = tmp_path / "target.csv"
    t = np.linspace(0.0, 4.0, 81)
    pd.DataFrame({"time_s": t, "yaw_deg": 3.0 + 2.0 * np.sin(t)}).to_csv(target, index=False)
    out = tmp_path / "comp" / "commands.csv"
    compensate_files([path], ["yaw+"], target, out, config=cfg)
    axis = json.loads((out.parent / "compensate.json").read_text())["axes"]["yaw"]
    rec = read_fit_json(path)["datasets"][0]["models"]["gpi"]
    assert axis["model"] == "gpi" and axis["params"] == rec["params"]
    assert axis["fit_replaced"] == rec["replaced"]["text"]


def test_no_lower_cost_leaves_fit_json_untouched(fitted, tmp_path):
    csv, out = fitted
    cfg = PipelineConfig()
    copy = tmp_path / "fit"
    shutil.copytree(out, copy)
    path = copy / "fit.json"
    stat = {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in copy.iterdir()}
    dset = diagnosis_dataset(csv, "yaw", "+", cfg.fit)
    stored = stored_fit_record(path, dset, cfg)
    same, _ = stored_model(*stored, "gpi", path)
    # the same values and a point 0.05 % away are the same minimum (the 0.1 % rule)
    x = np.array([p.value for p in same.parameters])
    near = same.with_values(x * (1 + 2e-5))
    auto = SimpleNamespace(
        paths={"gpi": SimpleNamespace(base_refits=(BaseRefit(same, "a"), BaseRefit(near, "b")))}
    )
    assert replace_stored_fit(path, stored, dset, auto, cfg) == []
    assert {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in copy.iterdir()} == stat


def test_a_fit_of_other_data_or_settings_is_refused_before_any_work(fitted, tmp_path):
    csv, out = fitted
    cfg = PipelineConfig()
    dset = diagnosis_dataset(csv, "yaw", "+", cfg.fit)
    other = PipelineConfig(fit=type(cfg.fit)(holdout_fraction=0.3))
    with pytest.raises(CalibError, match=r"other \[fit\] settings"):
        stored_fit_record(out / "fit.json", dset, other)
    changed = tmp_path / "synced.csv"
    shutil.copy(csv, changed)
    dset2 = diagnosis_dataset(changed, "yaw", "+", cfg.fit)
    with pytest.raises(CalibError, match="was fitted on"):
        stored_fit_record(out / "fit.json", dset2, cfg)
    with pytest.raises(CalibError, match="fit.json"):
        stored_fit_record(tmp_path / "nope.json", dset, cfg)


@pytest.mark.slow  # ~40 s: fit of every kind, then a diagnosis from gpi and egpi
def test_diagnose_fit_option_replaces_a_worse_stored_optimum_end_to_end(tmp_path, capsys):
    """`fit`, a fit.json whose egpi sits at a worse point, `diagnose --fit`: the
    diagnosis's refit of its egpi start costs less, fit.json is replaced and said so on
    the terminal, in diagnosis.json and diagnosis.md; a second `diagnose --fit` finds
    no lower cost and leaves fit.json byte-identical."""
    csv = tmp_path / "synced.csv"
    _synced(csv)
    out = tmp_path / "fit"
    assert main(["fit", str(csv), "--axis", "yaw", "--out", str(out)]) == 0
    path = out / "fit.json"
    doc = json.loads(path.read_text())
    doc["datasets"][0]["models"]["egpi"]["params"]["a1"] *= 1.3
    doc["models"] = doc["datasets"][0]["models"]
    path.write_text(json.dumps(doc, indent=2) + "\n")
    capsys.readouterr()
    args = ["diagnose", str(csv), "--axis", "yaw", "--fit", str(path), "--config"]
    cfg = tmp_path / "cfg.toml"
    cfg.write_text('[diagnose]\nmax_steps = 1\ncandidates = ["time_delay"]\n')
    assert main([*args, str(cfg), "--out", str(tmp_path / "d1")]) == 0
    said = capsys.readouterr().out
    rec = read_fit_json(path)["datasets"][0]["models"]["egpi"]["replaced"]
    assert rec["text"].startswith("fit.json's yaw+ egpi replaced: cost ")
    assert rec["found_by"].startswith("diagnose's refit")
    assert rec["text"] in said
    diag = json.loads((tmp_path / "d1" / "diagnosis.json").read_text())
    assert rec["text"] in [c["text"] for c in diag["fit_replaced"]]
    assert rec["text"] in (tmp_path / "d1" / "diagnosis.md").read_text()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main([*args, str(cfg), "--out", str(tmp_path / "d2")]) == 0
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert json.loads((tmp_path / "d2" / "diagnosis.json").read_text())["fit_replaced"] == []
