"""URDF export checked by an independent parser (yourdfpy): its forward kinematics equal the project's."""
from pathlib import Path

import numpy as np
import pytest

from campaign.config.simulation import simulated_cell
from campaign.config.load import load_cell
from campaign.report.export import UrdfLimits, export_model, robodk_text, urdf_text
from robocal.kinematics.models import Kinematics, fk, smr_base
from robocal.layers.calibrated_model import CalibratedModel
from robocal.simulation.mock_cell import random_geometric_errors

yourdfpy = pytest.importorskip("yourdfpy")
ROOT = Path(__file__).resolve().parents[3]
CONFIGS = sorted((ROOT / "configs").glob("*.yaml"))


def _limits(kin: Kinematics) -> UrdfLimits:
    return UrdfLimits(tuple(kin.q_min_rad), tuple(kin.q_max_rad), (1.0,) * kin.n)


def _max_error_um(kin: Kinematics, tmp_path: Path, n: int = 1000, seed: int = 0) -> float:
    path = tmp_path / "robot.urdf"
    path.write_text(urdf_text(CalibratedModel(kin), _limits(kin)))
    robot = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=True)
    rng = np.random.default_rng(seed)
    q = rng.uniform(kin.q_min_rad, kin.q_max_rad, (n, kin.n))
    T_ours = fk(kin, q)
    p_ours = smr_base(kin, q, T_ours)
    names = [f"j{i + 1}" for i in range(kin.n)]
    q_urdf = q.copy()
    if kin.track is not None:                 # the URDF's track joint: the actual travel in metres
        q_urdf[:, 0] = np.degrees(q[:, 0]) * np.linalg.norm(kin.track) / 1000.0
    worst = 0.0
    for k in range(n):
        robot.update_cfg(dict(zip(names, q_urdf[k])))
        T_flange = robot.get_transform("flange", "base_link")
        T_tool = robot.get_transform("tool", "base_link")
        worst = max(worst, np.max(np.abs(T_flange[:3, 3] * 1000 - T_ours[k, :3, 3])),
                    np.max(np.abs(T_tool[:3, 3] * 1000 - p_ours[k])),
                    1000 * np.max(np.abs(T_flange[:3, :3] - T_ours[k, :3, :3])))   # 1 m lever: rotation in um
    return worst * 1000.0


@pytest.mark.system
@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_urdf_of_each_shipped_cell_matches_fk(config, tmp_path):
    err = _max_error_um(load_cell(config).kinematics, tmp_path)
    print(f"{config.stem}: URDF vs FK max {err:.2e} um on 1000 poses")
    assert err <= 1.0


@pytest.mark.system
@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_urdf_of_a_calibrated_hayati_model_matches_fk(convention, tmp_path):
    truth = simulated_cell(load_cell(ROOT / "configs" / "irb2600.yaml")).truth    # DH + errors + Hayati beta on J2
    if convention == "mdh":
        truth = random_geometric_errors(truth.with_(convention="mdh"), np.random.default_rng(4), 3.0)
    assert np.any(truth.beta_rad != 0)
    err = _max_error_um(truth, tmp_path, seed=1)
    print(f"calibrated {convention}: URDF vs FK max {err:.2e} um on 1000 poses")
    assert err <= 1.0


@pytest.mark.unit
def test_urdf_of_a_calibrated_track_model_matches_fk(tmp_path):
    """A robot on a track: the URDF's prismatic joint along the identified direction, travel scaled, reproduces the
    chain (the simulated truth has the track's direction and scale off)."""
    truth = simulated_cell(load_cell(ROOT / "configs" / "irb2600_track.yaml")).truth
    assert abs(np.linalg.norm(truth.track) - 1) > 1e-6 and abs(truth.track[0]) > 1e-6
    err = _max_error_um(truth, tmp_path, n=300, seed=2)
    print(f"calibrated track: URDF vs FK max {err:.2e} um on 300 poses")
    assert err <= 1.0
    assert 'type="prismatic"' in (tmp_path / "robot.urdf").read_text()


@pytest.mark.unit
def test_robodk_refuses_a_track_in_one_line():
    from campaign.errors import DataError
    with pytest.raises(DataError) as err:
        robodk_text(CalibratedModel(load_cell(ROOT / "configs" / "irb2600_track.yaml").kinematics))
    assert "prismatic" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.unit
def test_wrong_origin_would_be_caught(tmp_path):
    """The comparison is sensitive: a 0.01 deg change of one alpha moves the tool by far more than 1 um."""
    kin = load_cell(ROOT / "configs" / "irb2600.yaml").kinematics
    path = tmp_path / "robot.urdf"
    bent = kin.with_(alpha_rad=kin.alpha_rad + np.r_[0, 0, np.radians(0.01), 0, 0, 0])
    path.write_text(urdf_text(CalibratedModel(bent), _limits(bent)))
    robot = yourdfpy.URDF.load(str(path), load_meshes=False)
    q = np.radians([10, 20, -30, 40, 50, 60])
    robot.update_cfg(dict(zip([f"j{i + 1}" for i in range(6)], q)))
    assert np.max(np.abs(robot.get_transform("tool", "base_link")[:3, 3] * 1000 - smr_base(kin, q[None])[0])) > 0.01


@pytest.mark.unit
def test_export_files_and_residual_note(tmp_path):
    cell = load_cell(ROOT / "configs" / "irb2600.yaml")
    from robocal.layers.idw import IDWResidual
    layer = IDWResidual.fit(np.random.default_rng(0).normal(size=(20, 3)) * 100, np.zeros((20, 3)), 2.0, 4)
    model = CalibratedModel(simulated_cell(cell).truth, layer)
    files = export_model(model, tmp_path / "r.urdf", tmp_path / "dh.csv", tmp_path / "robodk.txt",
                         limits=UrdfLimits.of_config(cell.config))
    assert [f.name for f in files] == ["r.urdf", "dh.csv", "robodk.txt"]
    assert "NOT exported: the non-kinematic residual layer" in (tmp_path / "r.urdf").read_text()
    rows = (tmp_path / "dh.csv").read_text().splitlines()
    assert rows[0].startswith("joint,convention,theta_deg,d_mm,a_mm,alpha_deg,beta_deg") and len(rows) == 8
    assert "beta_deg" in (tmp_path / "robodk.txt").read_text()     # Hayati beta: the table keeps the beta column


@pytest.mark.unit
def test_robodk_dhm_conversion_is_exact():
    """Standard DH without beta -> DHM rows; rebuilding the chain from the DHM rows gives the same FK."""
    kin = load_cell(ROOT / "configs" / "irb2600.yaml").kinematics
    text = robodk_text(CalibratedModel(kin))
    rows = [ln.split() for ln in text.splitlines() if ln and ln[0] == " " and ln.split()[0].isdigit()]
    table = np.array([[float(v) for v in r[1:5]] for r in rows])
    mdh = Kinematics.from_table("mdh", table[:, 0], table[:, 1], table[:, 3], table[:, 2],
                                np.degrees(kin.q_min_rad), np.degrees(kin.q_max_rad))
    q = np.random.default_rng(2).uniform(-1, 1, (50, 6))
    flange = [ln for ln in text.splitlines() if ln.startswith("# flange")][0]
    a_f, al_f = float(flange.split("Tx(")[1].split(" mm")[0]), float(flange.split("Rx(")[1].split(" deg")[0])
    from campaign.report.export import _rot, _trans
    T = fk(mdh, q) @ _trans("x", a_f) @ _rot("x", np.radians(al_f))
    assert np.max(np.abs(T[:, :3, 3] - fk(kin, q)[:, :3, 3])) < 1e-3


@pytest.mark.unit
def test_physical_effects_are_noted_not_exported(tmp_path):
    from robocal.effects.model import EffectChoice
    kin = load_cell(ROOT / "configs" / "irb2600.yaml").kinematics
    fake = type("FittedEffectStub", (), {"choice": EffectChoice("joint_compliance", (("joints", (2, 3)),))})()
    text = urdf_text(CalibratedModel(kin, None, None, (fake,)), _limits(kin))
    assert "NOT exported: the physical effects of the model (joint_compliance" in text


def _model_json(tmp_path: Path) -> Path:
    import json
    path = tmp_path / "model.json"
    path.write_text(json.dumps(CalibratedModel(simulated_cell(load_cell(ROOT / "configs" / "irb2600.yaml")).truth)
                               .to_dict()))
    return path


@pytest.mark.unit
def test_urdf_joint_limits_come_from_the_config(tmp_path, capsys):
    """campaign export --urdf --config: velocity = robot.max_joint_speed_deg_s in rad/s and the config's position
    limits, as yourdfpy reads them; effort omitted without --effort-nm, never a zero limit."""
    from campaign.cli import main

    config = ROOT / "configs" / "irb2600.yaml"
    cfg = load_cell(config).config
    model = _model_json(tmp_path)
    assert main(["export", str(model), "--urdf", str(tmp_path / "r.urdf"), "--config", str(config)]) == 0
    assert "effort limits omitted" in capsys.readouterr().out
    text = (tmp_path / "r.urdf").read_text()
    assert 'velocity="0"' not in text and 'effort="0"' not in text and "effort=" not in text.split("-->")[-1]
    robot = yourdfpy.URDF.load(str(tmp_path / "r.urdf"), load_meshes=False, build_scene_graph=False)
    for i, jc in enumerate(cfg.robot.joints):
        limit = robot.joint_map[f"j{i + 1}"].limit
        assert limit.velocity == pytest.approx(np.radians(cfg.robot.max_joint_speed_deg_s))
        assert (limit.lower, limit.upper) == pytest.approx((np.radians(jc.q_min_deg), np.radians(jc.q_max_deg)))
        assert limit.effort is None

    efforts = "1800,1800,900,200,200,120"
    assert main(["export", str(model), "--urdf", str(tmp_path / "e.urdf"), "--config", str(config),
                 "--effort-nm", efforts]) == 0
    robot = yourdfpy.URDF.load(str(tmp_path / "e.urdf"), load_meshes=False, build_scene_graph=False)
    assert [robot.joint_map[f"j{i + 1}"].limit.effort for i in range(6)] == [float(e) for e in efforts.split(",")]


@pytest.mark.unit
def test_urdf_without_config_or_with_bad_torques_is_one_line_exit_2(tmp_path, capsys):
    from campaign.cli import main

    model = _model_json(tmp_path)
    assert main(["export", str(model), "--urdf", str(tmp_path / "r.urdf")]) == 2
    assert "give --config CONFIG" in capsys.readouterr().err and not (tmp_path / "r.urdf").exists()
    config = str(ROOT / "configs" / "irb2600.yaml")
    assert main(["export", str(model), "--urdf", str(tmp_path / "r.urdf"), "--config", config,
                 "--effort-nm", "1,2"]) == 2
    assert "one positive torque (N*m) or 6" in capsys.readouterr().err
    assert main(["export", str(model), "--urdf", str(tmp_path / "r.urdf"), "--config", config,
                 "--effort-nm", "0"]) == 2
    assert main(["export", str(model), "--dh-csv", str(tmp_path / "dh.csv")]) == 0      # no URDF: no config needed


def _recorded_model(tmp_path: Path, kin: Kinematics, record: bool = True) -> Path:
    """DIR/model.json of ``kin`` with small errors and a parameter record (every joint parameter but the last
    joint's identified, std 0.001 * (1 + column)); ``record`` False: a model.json of an earlier version."""
    import json

    from robocal.kinematics.models import ParamLayout
    from robocal.identify.parameters import GEOMETRY, ParameterTable

    layout = ParamLayout.of(kin)
    cal = kin.with_(a_mm=kin.a_mm + 0.3, alpha_rad=kin.alpha_rad + 1e-4, theta_rad=kin.theta_rad - 2e-4)
    ident = [n for n in layout.names if n[-1].isdigit() and not n.endswith(str(kin.n))]
    std = np.where(np.isin(layout.names, ident), 0.001 * (1 + np.arange(layout.size)), np.nan)
    doc = CalibratedModel(cal, parameters=ParameterTable.of(cal, kin, ident, std, GEOMETRY, 1.0)).to_dict()
    if not record:
        del doc["parameters"]
    (tmp_path / "model.json").write_text(json.dumps(doc))
    return tmp_path


@pytest.mark.unit
def test_every_export_carries_the_records_values_and_std(tmp_path):
    """DH CSV, RoboDK table (the exact DHM form: std of alpha, a from the previous DH joint) and URDF comments of a
    standard-DH model without beta print its record's values and std (the same checks as the campaign runs)."""
    from tests.campaign.one_record import check_dh_csv, check_robodk, check_urdf, export_all

    config = ROOT / "configs" / "irb2600.yaml"
    out = _recorded_model(tmp_path, load_cell(config).kinematics)
    files = export_all(out, config)
    assert "converted exactly" in files["robodk"].read_text()
    assert check_dh_csv(files["dh"], out) == 25 and check_robodk(files["robodk"], out) == 6 * 4 - 2
    assert check_urdf(files["urdf"], out) < 1e-9


@pytest.mark.unit
def test_a_model_json_without_a_record_still_exports(tmp_path):
    """model.json of an earlier version (no ``parameters``): loaded, exported with the std left empty and said so."""
    config = ROOT / "configs" / "irb2600.yaml"
    out = _recorded_model(tmp_path, load_cell(config).kinematics, record=False)
    from tests.campaign.one_record import export_all

    files = export_all(out, config)
    rows = files["dh"].read_text().splitlines()
    assert rows[1].endswith(",,,,,") and "parameter std: not recorded" in files["urdf"].read_text()
    assert "not recorded" in files["robodk"].read_text()
