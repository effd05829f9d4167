"""`campaign diagnose`: JSON contract on an interchange CSV from a simulated campaign, noise-floor source,
one-line errors (exit 2), plots (optional extra) and the self-check entry point."""
import importlib.util
import json

import numpy as np
import pytest

from campaign.cli import main
from campaign.interchange import Dataset, write_csv
from robocal.selfcheck import simulate_campaign
from tests.campaign.helpers import small_config

EFFECTS = {"joint_compliance", "gear_cyclic", "backlash", "readback_lag", "thermal_drift", "axis_coupling", "registration_drift",
           "payload_deflection"}


def campaign_csv(tmp_path, effects, seed, drop_check=False, name="data.csv"):
    """Interchange CSV of a simulated campaign (rows in measurement order) and a config with its nominal SMR."""
    camp = simulate_campaign(effects, seed, magnitude=1.0)
    keep = np.array([not (drop_check and s == "check") for s in camp.sets])
    ds = Dataset(tuple(np.array(camp.point_id)[keep]), tuple(np.array(camp.sets)[keep]),
                 np.degrees(camp.q_rad[keep]), camp.p_mm[keep], t_s=camp.t_s[keep], payload_kg=camp.payload_kg[keep])
    path = tmp_path / name
    write_csv(path, ds)
    cfg = small_config(tmp_path, **{"tool.p_flange_smr_mm": [float(x) for x in camp.nominal.p_flange_smr_mm]})
    return path, cfg, camp


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("diag")
    csv, cfg, camp = campaign_csv(tmp, ["backlash", "axis_coupling"], 51)
    out = tmp / "report.json"
    code = main(["diagnose", str(csv), "--config", str(cfg), "--json", str(out)])
    return code, json.loads(out.read_text()), camp


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
        assert isinstance(f["test_rms_before_mm"], float) and isinstance(f["test_rms_after_mm"], float)
    for w in rep["where"]:
        assert isinstance(w["description"], str) and isinstance(w["rms_mm"], float)
        assert "vs floor" in w["description"]


@pytest.mark.system
def test_the_withheld_effects_are_found_and_the_gap_shrinks_to_the_floor(diagnosed):
    _, rep, camp = diagnosed
    found = {f["effect"]: f for f in rep["findings"] if f["accepted"]}
    assert set(found) == {"backlash", "axis_coupling"}
    truth = {t.name: t for t in camp.truths}
    assert tuple(found["backlash"]["joints"]) == truth["backlash"].joints
    assert rep["noise_floor_source"] == "repeats"
    assert rep["final_test_rms_mm"] < 1.25 * rep["noise_floor_mm"] < rep["baseline_test_rms_mm"]
    for f in found.values():
        assert f["test_rms_after_mm"] < f["test_rms_before_mm"]
    # where: the approach-direction split of a backlash joint is named
    joint = truth["backlash"].joints[0]
    assert any(w["description"].startswith(f"J{joint} approach direction") for w in rep["where"])
    # nothing undiagnosable in a full protocol; the report says where the figures come from
    assert rep["undiagnosable"] == [] and rep["evaluation"] == "test"


@pytest.mark.system
def test_noise_floor_from_specs_without_repeats(tmp_path, capsys):
    csv, cfg, _ = campaign_csv(tmp_path, [], 52, drop_check=True)
    out = tmp_path / "r.json"
    assert main(["diagnose", str(csv), "--config", str(cfg), "--json", str(out)]) == 0
    rep = json.loads(out.read_text())
    assert rep["noise_floor_source"] == "specs" and rep["noise_floor_repeats_mm"] is None
    assert not [f for f in rep["findings"] if f["accepted"]]
    assert "Which effect" in capsys.readouterr().out


@pytest.mark.system
def test_bad_csv_is_one_line_exit_2(tmp_path, capsys):
    csv, cfg, _ = campaign_csv(tmp_path, [], 53)
    lines = csv.read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[4], "abc", 1)
    csv.write_text("\n".join(lines) + "\n")
    assert main(["diagnose", str(csv), "--config", str(cfg)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert err.startswith(f"error: {csv}: line 6, column 'q3': expected a number, got 'abc'")


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
    csv, cfg, _ = campaign_csv(tmp_path, ["gear_cyclic"], 54)
    if importlib.util.find_spec("matplotlib") is None:
        assert main(["diagnose", str(csv), "--config", str(cfg), "--plots", str(tmp_path / "png")]) == 0
        out = capsys.readouterr().out
        assert "matplotlib is not installed: no plots" in out
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
    import robocal.selfcheck as sc
    monkeypatch.setattr(sc, "trial_plan", lambda seeds, *a, **k: [("single", ("backlash",), 61),
                                                                  ("control", (), 62), ("combo", ("gear_cyclic",
                                                                                                  "axis_coupling"), 63)])
    out = tmp_path / "self.json"
    assert main(["diagnose", "--self-check", "--seeds", "1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "truth \\ diagnosed" in text and "correctly attributed" in text and "controls" in text
    rep = json.loads(out.read_text())
    assert rep["passed"] and rep["confusion"]["backlash"]["backlash"] == 1 and rep["confusion"]["none"]["none"] == 1
    assert main(["diagnose", "--self-check", "--seeds", "0"]) == 2


@pytest.mark.system
def test_diagnose_baseline_is_the_reprocess_kinematic_stage(tmp_path):
    """"Before" agrees everywhere: the diagnosis starts from campaign.process.geometric_fit, the fit whose test RMS
    reprocess reports as its kinematic stage (same CSV, same config, default robust estimator)."""
    from campaign.config import load_config
    from campaign.diagnose import diagnose_source
    from campaign.interchange import read_csv
    from campaign.process import process
    from robocal.truth import TruthProtocol, simulate

    camp = simulate(["joint_compliance"], 71, TruthProtocol(n_calib=160, n_test=60, check_poses=6, check_repeats=4))
    keep = np.ones(len(camp.sets), bool)
    ds = Dataset(camp.point_id, camp.sets, np.degrees(camp.q_read_rad), camp.p_mm, t_s=camp.t_s,
                 payload_kg=camp.payload_kg)
    path = tmp_path / "truth.csv"
    write_csv(path, ds)
    cfg = load_config(small_config(tmp_path, **{"tool.p_flange_smr_mm": [float(x) for x in camp.nominal.p_flange_smr_mm]}))
    kinematic = process(read_csv(path), cfg).report["stages"]["kinematic"]["test"]["rms_mm"]
    rep = diagnose_source(path, cfg).report
    assert keep.all() and rep["baseline_test_rms_mm"] == pytest.approx(kinematic, rel=1e-6)
    assert rep["final_test_rms_mm"] < rep["baseline_test_rms_mm"]
    assert "joint_compliance" in {f["effect"] for f in rep["findings"] if f["accepted"]}


class _DatasetWithNests:
    """Duck-typed dataset with the fields the calibration issue adds (commanded joints qc_deg, rows of set "nest"
    with nest_id and empty joints), so the diagnosis adapter is exercised before those land in Dataset."""

    def __init__(self, camp):
        n_rows = len(camp.sets)
        order, sets, ids = [], [], []
        after = {int(r): [] for r in camp.nest_after_row}
        for k, r in enumerate(camp.nest_after_row):
            after[int(r)].append(k)
        for i in range(n_rows):
            order.append(("row", i))
            order += [("nest", k) for k in after.get(i, [])]
        q, qc, p, t, pay = [], [], [], [], []
        for kind, i in order:
            if kind == "row":
                q.append(np.degrees(camp.q_read_rad[i]))
                qc.append(np.degrees(camp.q_cmd_rad[i]))
                p.append(camp.p_mm[i])
                t.append(camp.t_s[i])
                pay.append(camp.payload_kg[i])
                sets.append(camp.sets[i])
                ids.append("")
            else:
                q.append(np.full(6, np.nan))
                qc.append(np.full(6, np.nan))
                p.append(camp.nest_p_mm[i])
                t.append(camp.nest_t_s[i])
                pay.append(0.0)
                sets.append("nest")
                ids.append(camp.nest_id[i])
        self.set, self.nest_id = tuple(sets), tuple(ids)
        self.point_id = tuple(f"R{i}" for i in range(len(sets)))
        self.q_deg, self.qc_deg, self.p_tracker_mm = np.array(q), np.array(qc), np.array(p)
        self.t_s, self.payload_kg, self.temp_c = np.array(t), np.array(pay), None
        self.source, self.n_joints = "nests.csv", 6

    def mask(self, name):
        return np.array([s == name for s in self.set])


@pytest.mark.unit
def test_adapter_uses_commanded_joints_and_reference_nests(tmp_path):
    from campaign.config import load_config
    from campaign.diagnose import diagnosis_input
    from robocal.diagnose import diagnose
    from robocal.truth import TruthProtocol, simulate

    camp = simulate(["readback_lag"], 72, TruthProtocol(n_calib=160, n_test=60, check_poses=6, check_repeats=4,
                                                        nest_every=10))
    ds = _DatasetWithNests(camp)
    cfg = load_config(small_config(tmp_path, **{"tool.p_flange_smr_mm": [float(x) for x in camp.nominal.p_flange_smr_mm]}))
    inp, info = diagnosis_input(ds, cfg)
    assert info["metadata"]["commanded_joints"] and info["metadata"]["reference_nests"] == 3
    assert inp.qc_rad is not None and np.all(np.isfinite(inp.q_rad))
    assert len(inp.q_rad) == int(ds.mask("calib").sum() + ds.mask("test").sum())
    assert np.all(np.isfinite(inp.move_rad))            # nest rows (no joints) do not break the moves
    d = diagnose(inp)
    lag = next(f for f in d.findings if f.effect == "readback_lag")
    assert lag.accepted and set(lag.evidence["direct_comparison"]) >= {f"J{j}" for j in camp.truths[0].joints}
    reg = next(f for f in d.findings if f.effect == "registration_drift")
    assert "ruled out by the reference nests" in reg.evidence["reason"]
