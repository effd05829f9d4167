"""Hostile configs (issue 12): every one gives exit 2 and ONE stderr line naming the file and the key, fast,
with no traceback and nothing written. Whatever ``validate`` accepts, ``run`` accepts (see the property test)."""
from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from tests.campaign.helpers import ROOT
from tests.campaign.hostile import assert_one_line, cli, snapshot

BASE = yaml.safe_load((ROOT / "configs" / "irb2600.yaml").read_text())


def _set(path: str, value) -> Callable[[dict], dict]:
    """Mutation setting a dotted key path (``a.b[2].c``) to ``value``."""
    def apply(doc: dict) -> dict:
        node, keys = doc, _keys(path)
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value
        return doc
    return apply


def _delete(path: str) -> Callable[[dict], dict]:
    def apply(doc: dict) -> dict:
        node, keys = doc, _keys(path)
        for k in keys[:-1]:
            node = node[k]
        del node[keys[-1]]
        return doc
    return apply


def _keys(path: str) -> list:
    out = []
    for part in path.split("."):
        name, _, idx = part.partition("[")
        out.append(name)
        if idx:
            out.append(int(idx.rstrip("]")))
    return out


def _joints(n: int) -> Callable[[dict], dict]:
    def apply(doc: dict) -> dict:
        rows = doc["robot"]["joints"]
        doc["robot"]["joints"] = (rows * 3)[:n]
        doc["plan"]["q_ref_deg"] = ([0, 0, 0, 0, 45, 0] * 3)[:n]
        doc["robot"]["hayati_joints"] = []
        return doc
    return apply


@dataclass(frozen=True)
class Case:
    """A hostile config: a mutation of the reference dict, or raw bytes; the key path (or text) the line names."""
    mutate: Callable[[dict], dict] | None = None
    raw: bytes | None = None
    needles: tuple[str, ...] = ()


BOMB = b"""name: bomb
robot:
  options:
    a: &a ["x","x","x","x","x","x","x","x","x","x"]
    b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a,*a]
    c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b,*b]
    d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c,*c]
    e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d,*d]
    f: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e,*e]
    g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f,*f]
    h: &h [*g,*g,*g,*g,*g,*g,*g,*g,*g,*g]
"""

CASES: dict[str, Case] = {
    # file level
    "empty_file": Case(raw=b"", needles=("empty config",)),
    "top_level_list": Case(raw=b"- a\n- b\n", needles=("top level must be a mapping",)),
    "malformed_yaml": Case(raw=b"name: [unclosed\nrobot: {\n", needles=("malformed YAML",)),
    "duplicate_key": Case(raw=b"name: a\nname: b\n", needles=("duplicate key",)),
    "alias_bomb_in_robot_options": Case(raw=BOMB, needles=("alias",)),
    "recursive_alias": Case(raw=b"name: &a [*a]\n", needles=("YAML",)),
    "file_over_1_MiB": Case(raw=b"# " + b"x" * (1 << 20) + b"\n", needles=("larger than",)),
    "not_utf8": Case(raw=b"name: \xff\xfe\n", needles=("UTF-8",)),
    "deep_nesting": Case(raw=b"name: " + b"[" * 5000 + b"]" * 5000 + b"\n", needles=("YAML",)),
    # keys and types
    "missing_name": Case(_delete("name"), needles=("name",)),
    "name_with_slash": Case(_set("name", "a/b"), needles=("name",)),
    "missing_robot": Case(_delete("robot"), needles=("robot",)),
    "unknown_top_key": Case(_set("robto", {}), needles=("robto", "unknown key")),
    "url_without_scheme": Case(_set("robot.url", "192.168.125.1"), needles=("robot.url",)),
    "url_unknown_driver": Case(_set("robot.url", "kuka://10.0.0.1"), needles=("robot.url", "kuka")),
    "abb_rws_without_host": Case(_set("robot.url", "abb-rws://"), needles=("robot.url", "host")),
    "ur_rtde_with_port": Case(_set("robot.url", "ur-rtde://10.0.0.5:30004"), needles=("robot.url", "port")),
    "tracker_socket_without_port": Case(_set("tracker.url", "tracker+socket://localhost"),
                                        needles=("tracker.url", "host:port")),
    "tracker_socket_bad_port": Case(_set("tracker.url", "tracker+socket://localhost:99999"),
                                    needles=("tracker.url",)),
    "emscon_without_host": Case(_set("tracker.url", "emscon://"), needles=("tracker.url", "HOST")),
    "emscon_option_typo": Case(lambda d: _set("tracker.options", {"meas_tme_ms": 100})(
        _set("tracker.url", "emscon://10.0.0.2")(d)), needles=("tracker.options", "meas_tme_ms")),
    "tracker_serial_without_device": Case(_set("tracker.url", "tracker+serial://"), needles=("tracker.url",)),
    "tracker_option_typo": Case(lambda d: _set("tracker.options", {"tiemout_s": 2})(
        _set("tracker.url", "tracker+socket://127.0.0.1:7000")(d)), needles=("tracker.options", "tiemout_s")),
    "tracker_option_bad_value": Case(lambda d: _set("tracker.options", {"timeout_s": -1})(
        _set("tracker.url", "tracker+socket://127.0.0.1:7000")(d)), needles=("tracker.options", "timeout_s")),
    "mock_robot_with_options": Case(_set("robot.options", {"speed": 3}), needles=("robot.options", "speed")),
    "abb_option_typo": Case(lambda d: _set("robot.options", {"tsak": "T_ROB1"})(
        _set("robot.url", "abb-rws://192.168.125.1")(d)), needles=("robot.options", "tsak")),
    "ur_option_bad_value": Case(lambda d: _set("robot.options", {"speed_rad_s": 100})(
        _set("robot.url", "ur-rtde://10.0.0.5")(d)), needles=("robot.options", "speed_rad_s")),
    "convention_unknown": Case(_set("robot.convention", "xyz"), needles=("robot.convention",)),
    "joints_empty": Case(_set("robot.joints", []), needles=("robot.joints",)),
    "thirteen_joints": Case(_joints(13), needles=("robot.joints",)),
    "one_joint": Case(_joints(1), needles=("robot.joints", "4 to 7 joints")),
    "two_joints": Case(_joints(2), needles=("robot.joints", "4 to 7 joints")),
    "eight_joints": Case(_joints(8), needles=("robot.joints", "4 to 7 joints", "got 8")),
    "q_min_above_q_max": Case(_set("robot.joints[1].q_min_deg", 200), needles=("robot.joints[1].q_max_deg",)),
    "a_mm_nan": Case(_set("robot.joints[0].a_mm", float("nan")), needles=("robot.joints[0].a_mm", "finite")),
    "a_mm_text_exponent": Case(_set("robot.joints[0].a_mm", "1e-6"), needles=("robot.joints[0].a_mm",)),
    "hayati_last_joint": Case(_set("robot.hayati_joints", [6]), needles=("robot.hayati_joints[0]", "last joint")),
    "hayati_non_parallel": Case(_set("robot.hayati_joints", [1]), needles=("robot.hayati_joints[0]", "parallel")),
    "hayati_zero": Case(_set("robot.hayati_joints", [0]), needles=("robot.hayati_joints[0]",)),
    # sizes that allocate or loop
    "step_1_mm": Case(_set("plan.grid.step_mm", 1), needles=("plan.grid.step_mm", "grid points")),
    "step_zero": Case(_set("plan.grid.step_mm", 0), needles=("plan.grid.step_mm",)),
    "step_negative": Case(_set("plan.grid.step_mm", -200), needles=("plan.grid.step_mm",)),
    "step_tiny": Case(_set("plan.grid.step_mm", 1e-300), needles=("plan.grid.step_mm",)),
    "test_count_1e7": Case(_set("plan.test.count", 10_000_000), needles=("plan.test.count", "at most")),
    "test_count_float": Case(_set("plan.test.count", 1e7), needles=("plan.test.count",)),
    "samples_1e12": Case(_set("tracker.measurement.samples", 10**12), needles=("tracker.measurement.samples",)),
    "samples_zero": Case(_set("tracker.measurement.samples", 0), needles=("tracker.measurement.samples",)),
    "retries_1000": Case(_set("tracker.measurement.retries", 1000), needles=("tracker.measurement.retries",)),
    "settle_1e9_s": Case(_set("tracker.measurement.settle_s", 1e9), needles=("tracker.measurement.settle_s",)),
    "timeout_zero": Case(_set("tracker.measurement.timeout_s", 0), needles=("tracker.measurement.timeout_s",)),
    "check_poses_1000": Case(_set("plan.check_poses", {"count": 1000, "every_n_points": 1}),
                             needles=("plan.check_poses.count",)),
    "check_every_point_many": Case(lambda d: _set("plan.check_poses", {"count": 100, "every_n_points": 1})(
        _set("plan.test.count", 5000)(d)), needles=("plan.check_poses.every_n_points",)),
    "closed_loop_1000": Case(_set("correction", {"closed_loop_iterations": 1000}),
                             needles=("correction.closed_loop_iterations",)),
    "max_iterations_1e9": Case(_set("correction", {"max_iterations": 10**9}), needles=("correction.max_iterations",)),
    "motion_time_huge": Case(_set("simulation.motion_time_s", 1e12), needles=("simulation.motion_time_s",)),
    # geometry
    "q_ref_wrong_length": Case(_set("plan.q_ref_deg", [0, 0, 0]), needles=("plan.q_ref_deg",)),
    "q_ref_outside_limits": Case(_set("plan.q_ref_deg", [0, 0, 0, 0, 500, 0]), needles=("plan.q_ref_deg[4]",)),
    "tool_direction_zero": Case(_set("plan.tool_direction", [0, 0, 0]), needles=("plan.tool_direction",)),
    "grid_out_of_reach": Case(_set("plan.grid.center_mm", [9000, 0, 0]), needles=("plan.grid.center_mm", "reach")),
    "grid_size_negative": Case(_set("plan.grid.size_mm", [-1, 1, 1]), needles=("plan.grid.size_mm[0]",)),
    "T_tracker_base_not_rigid": Case(_set("simulation.T_tracker_base", [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0],
                                                                        [0, 0, 0, 1]]),
                                     needles=("simulation.T_tracker_base", "orthonormal")),
    "smr3_without_smr2": Case(_set("tool.p_flange_smr3_mm", [50, 0, 40]), needles=("tool.p_flange_smr3_mm",)),
    "k1_below_k0": Case(_set("calibration.k1", 1.0), needles=("calibration.k1",)),
    "idw_k_zero": Case(_set("calibration.idw_k_nearest", 0), needles=("calibration.idw_k_nearest",)),
    "output_dir_empty": Case(_set("output", {"dir": ""}), needles=("output.dir",)),
    # effects
    "effect_unknown": Case(_set("simulation.effects", ["warp_drive"]), needles=("simulation.effects[0].name",)),
    "effect_param_unknown": Case(_set("simulation.effects", [{"name": "backlash", "params": {"jonts": [2]}}]),
                                 needles=("simulation.effects[0].params", "jonts")),
    "effect_joint_99": Case(_set("simulation.effects", [{"name": "gear_cyclic", "params": {"joint": 99}}]),
                            needles=("simulation.effects[0].params",)),
    "effect_values_count": Case(_set("simulation.effects", [{"name": "backlash", "params": {"values": [1, 2, 3, 4, 5, 6, 7, 8, 9]}}]),
                                needles=("simulation.effects[0].params.values",)),
    "effect_huge": Case(_set("simulation.effects", [{"name": "joint_compliance", "scale": 1e9}]),
                        needles=("simulation.effects[0]", "moves the SMR")),
    "effect_duplicate": Case(_set("simulation.effects", ["backlash", "backlash"]),
                             needles=("simulation.effects[1].name", "duplicate")),
    "fault_probability_2": Case(_set("simulation.faults", {"beam_break_probability": 2}),
                                needles=("simulation.faults.beam_break_probability",)),
}


def _write(tmp_path: Path, case: Case) -> Path:
    path = tmp_path / "hostile.yaml"
    if case.raw is not None:
        path.write_bytes(case.raw)
    else:
        doc = case.mutate(copy.deepcopy(BASE))
        doc["output"] = doc.get("output") or {"dir": str(tmp_path / "runs")}
        path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


@pytest.mark.system
def test_table_size():
    assert len(CASES) >= 40


@pytest.mark.system
@pytest.mark.parametrize("name", sorted(CASES))
def test_hostile_config(name, tmp_path, capsys, monkeypatch):
    """validate, plan and run all refuse it with the same one line, exit 2; nothing is written."""
    monkeypatch.chdir(tmp_path)
    path = _write(tmp_path, CASES[name])
    before = snapshot(tmp_path)
    lines = set()
    for command in (["validate"], ["plan"], ["run"]):
        code, out, err = cli(capsys, *command, path)
        lines.add(assert_one_line(code, out, err, 2, str(path), *CASES[name].needles))
    assert len(lines) == 1                 # one schema: the same message from every command
    assert snapshot(tmp_path) == before


@pytest.mark.system
def test_shipped_configs_validate(capsys):
    for path in sorted((ROOT / "configs").glob("*.yaml")):
        code, out, err = cli(capsys, "validate", path)
        assert code == 0 and out.startswith("OK"), err
