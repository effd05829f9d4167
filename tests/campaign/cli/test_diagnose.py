"""`campaign diagnose`: JSON contract on an interchange CSV of a truth campaign, the same figures in the terminal and
the JSON, noise-floor source, the dataset preparation shared with reprocess, one-line errors (exit 2), plots
(optional extra) and the self-check entry point."""
import importlib.util
import json

import numpy as np
import pytest

from campaign.cli import main
from campaign.data.dataset import Dataset
from campaign.data.interchange_csv import write_csv
from robocal.simulation.truth_cell import TruthProtocol, simulate
from tests.campaign.helpers import small_config, truth_csv

EFFECTS = {"joint_compliance", "gear_cyclic", "backlash", "readback_lag", "thermal_drift", "axis_coupling",
           "registration_drift", "payload_deflection"}
SMALL = TruthProtocol(n_calib=160, n_test=60, check_poses=6, check_repeats=4)


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("diag")
    camp = simulate(["backlash", "axis_coupling"], 51, SMALL, scale=1.0)
    csv, cfg = truth_csv(tmp, camp)
    out = tmp / "report.json"
    return main(["diagnose", str(csv), "--config", str(cfg), "--json", str(out)]), json.loads(out.read_text()), camp


@pytest.mark.system
def test_json_contract(diagnosed):
    code, rep, _ = diagnosed
    assert code == 0
    assert list(rep)[:7] == ["noise_floor_mm", "noise_floor_source", "baseline_test_rms_mm", "final_test_rms_mm",
                             "unexplained", "findings", "where"]
    for key in ("noise_floor_mm", "baseline_test_rms_mm", "final_test_rms_mm"):
        assert isinstance(rep[key], float) and rep[key] > 0
    assert rep["noise_floor_source"] in ("repeats", "specs") and isinstance(rep["unexplained"], bool)
    assert rep["findings"] and rep["where"]
    for f in rep["findings"]:
        assert set(f) == {"effect", "joints", "accepted", "test_rms_before_mm", "test_rms_after_mm", "evidence"}
        assert f["effect"] in EFFECTS and isinstance(f["accepted"], bool) and isinstance(f["evidence"], dict)
        assert all(isinstance(j, int) and 1 <= j <= 6 for j in f["joints"])
    for w in rep["where"]:
        assert isinstance(w["description"], str) and "vs floor" in w["description"]
    assert set(rep["unexplained_structure"]) >= {"heldout_rms_mm", "floor_mm", "excess_over_floor_mm",
                                                 "layer_heldout_rms_mm", "layer_removes_mm", "text"}


@pytest.mark.system
def test_the_withheld_effects_are_found_and_the_gap_shrinks_to_the_floor(diagnosed):
    _, rep, camp = diagnosed
    found = {f["effect"]: f for f in rep["findings"] if f["accepted"]}
    assert set(found) == {"backlash", "axis_coupling"}
    truth = {t.name: t for t in camp.truths}
    assert tuple(found["backlash"]["joints"]) == truth["backlash"].joints
    assert rep["noise_floor_source"] == "repeats" and rep["evaluation"] == "test"
    assert rep["final_test_rms_mm"] < 1.3 * rep["noise_floor_mm"] < rep["baseline_test_rms_mm"]
    for f in found.values():
        assert f["test_rms_after_mm"] < f["test_rms_before_mm"]
    joint = truth["backlash"].joints[0]
    assert any(w["description"].startswith(f"J{joint} approach direction") for w in rep["where"])
    assert rep["engine"].startswith("the elastic stage of reprocess")


@pytest.mark.system
def test_terminal_prints_the_json_figures_of_the_leftover(tmp_path, capsys):
    camp = simulate(["reach_deflection"], 52, SMALL, scale=3.0)
    csv, cfg = truth_csv(tmp_path, camp)
    out = tmp_path / "r.json"
    assert main(["diagnose", str(csv), "--config", str(cfg), "--json", str(out)]) == 0
    text = " ".join(capsys.readouterr().out.split())
    u = json.loads(out.read_text())["unexplained_structure"]
    assert " ".join(u["text"].split()) in text
    assert f"{u['excess_over_floor_mm']:.3f} mm" in u["text"] and f"{u['layer_removes_mm']:.3f} mm" in u["text"]


@pytest.mark.system
def test_noise_floor_from_specs_without_repeats(tmp_path, capsys):
    camp = simulate([], 53, SMALL)
    csv, cfg = truth_csv(tmp_path, camp)
    lines = [ln for ln in csv.read_text().splitlines() if ",check," not in ln]
    csv.write_text("\n".join(lines) + "\n")
    out = tmp_path / "r.json"
    assert main(["diagnose", str(csv), "--config", str(cfg), "--json", str(out)]) == 0
    rep = json.loads(out.read_text())
    assert rep["noise_floor_source"] == "specs" and rep["noise_floor_repeats_mm"] is None
    assert not [f for f in rep["findings"] if f["accepted"]]
    assert "Which effect" in capsys.readouterr().out


@pytest.mark.system
def test_commanded_joints_are_chosen_as_reprocess_does_and_the_lag_is_then_gone(tmp_path):
    """Read-back joints with a lag next to the commanded ones: the preparation (shared with reprocess) takes the
    commanded joints, so neither a lag nor backlash is accepted."""
    camp = simulate(["readback_lag"], 54, SMALL)
    ds = Dataset(camp.point_id, camp.sets, np.degrees(camp.q_read_rad), camp.p_mm, t_s=camp.t_s,
                 payload_kg=camp.payload_kg, qc_deg=np.degrees(camp.q_cmd_rad))
    csv, cfg = truth_csv(tmp_path, camp)
    write_csv(csv, ds)
    out = tmp_path / "r.json"
    assert main(["diagnose", str(csv), "--config", str(cfg), "--json", str(out)]) == 0
    rep = json.loads(out.read_text())
    assert rep["preparation"]["joints"]["used"] == "commanded"
    assert not {"readback_lag", "backlash"} & {f["effect"] for f in rep["findings"] if f["accepted"]}


@pytest.mark.system
def test_bad_csv_and_unknown_effects_in_the_config_are_one_line_exit_2(tmp_path, capsys):
    csv, cfg = truth_csv(tmp_path, simulate([], 55, SMALL))
    text = csv.read_text()
    lines = text.splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[4], "abc", 1)
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    assert main(["diagnose", str(tmp_path / "bad.csv"), "--config", str(cfg)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "line 6, column 'q3': expected a number, got 'abc'" in err
    for effects, key in (([{"name": "link_bending"}], "calibration.effects[0].name"),
                         ([{"name": "backlash", "params": {"joints": [1], "width": 2}}],
                          "calibration.effects[0].params.width")):
        bad = small_config(tmp_path, **{"calibration.effects": effects})
        for cmd in ("diagnose", "reprocess"):
            args = [cmd, str(csv), "--config", str(bad)] + (["--out", str(tmp_path / "o")] if cmd == "reprocess" else [])
            assert main(args) == 2
            err = capsys.readouterr().err.strip()
            assert err.count("\n") == 0 and key in err


@pytest.mark.parametrize("args,message", [
    (["diagnose"], "needs RUN_DIR_OR_CSV and --config"),
    (["diagnose", "missing.csv", "--config", "CFG"], "missing.csv: no such file or run directory"),
    (["diagnose", "--self-check", "data.csv"], "--self-check takes no data"),
])
@pytest.mark.system
def test_usage_errors_are_one_line_exit_2(tmp_path, capsys, args, message):
    cfg = small_config(tmp_path)
    args = [str(cfg) if a == "CFG" else str(tmp_path / a) if a.endswith(".csv") else a for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err


@pytest.mark.system
def test_wrong_joint_count_and_too_few_rows_exit_2(tmp_path, capsys):
    rows = ["point_id,set,q1,q2,q3,x,y,z"] + [f"P{i},calib,{i},{i},{i},1,2,{i}" for i in range(50)]
    (tmp_path / "three.csv").write_text("\n".join(rows) + "\n")
    cfg = small_config(tmp_path)
    assert main(["diagnose", str(tmp_path / "three.csv"), "--config", str(cfg)]) == 2
    assert "has 3 joint columns but the config's robot has 6 joints" in capsys.readouterr().err
    rows = ["point_id,set,q1,q2,q3,q4,q5,q6,x,y,z"] + [f"P{i},calib,{i},{i},{i},0,30,0,1,2,{i}" for i in range(12)]
    (tmp_path / "few.csv").write_text("\n".join(rows) + "\n")
    assert main(["diagnose", str(tmp_path / "few.csv"), "--config", str(cfg)]) == 2
    assert "only 12 calib rows: the diagnosis needs at least 40" in capsys.readouterr().err


@pytest.mark.system
def test_plots_or_a_one_line_note(tmp_path, capsys, monkeypatch):
    csv, cfg = truth_csv(tmp_path, simulate(["gear_cyclic"], 56, SMALL))
    if importlib.util.find_spec("matplotlib") is None:
        assert main(["diagnose", str(csv), "--config", str(cfg), "--plots", str(tmp_path / "png")]) == 0
        assert "matplotlib is not installed: no plots" in capsys.readouterr().out
        assert not (tmp_path / "png").exists()
    else:
        assert main(["diagnose", str(csv), "--config", str(cfg), "--plots", str(tmp_path / "png")]) == 0
        names = {p.name for p in (tmp_path / "png").iterdir()}
        assert {"where_workspace.png", "where_joints.png", "shrinkage.png", "where_time.png"} <= names
        import builtins
        real_import = builtins.__import__

        def no_matplotlib(name, *a, **k):
            if name.startswith("matplotlib"):
                raise ImportError(name)
            return real_import(name, *a, **k)
        monkeypatch.setattr(builtins, "__import__", no_matplotlib)
        assert main(["diagnose", str(csv), "--config", str(cfg), "--plots", str(tmp_path / "png2")]) == 0
        assert "matplotlib is not installed: no plots" in capsys.readouterr().out


@pytest.mark.system
def test_self_check_entry_point_prints_the_confusion_matrix_and_writes_json(tmp_path, capsys, monkeypatch):
    from robocal.diagnose import selfcheck as sc
    monkeypatch.setattr(sc, "trial_plan", lambda seeds, *a, **k: [("single", ("backlash",), 61),
                                                                  ("control", (), 62),
                                                                  ("order_gear", ("gear_cyclic",), 63)])
    out = tmp_path / "self.json"
    assert main(["diagnose", "--self-check", "--seeds", "1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "truth \\ diagnosed" in text and "correctly attributed" in text and "order_gear: named right 1/1" in text
    rep = json.loads(out.read_text())
    assert rep["passed"] and rep["confusion"]["backlash"]["backlash"] == 1 and rep["confusion"]["none"]["none"] == 1
    assert main(["diagnose", "--self-check", "--seeds", "0"]) == 2
