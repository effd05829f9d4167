"""Tests for campaign.config.load, campaign.errors and the ``validate`` CLI command."""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import json
import math
import pickle
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import pytest
import yaml

from campaign import cli
from campaign.cli import main
from campaign.config.schema import EffectSpec
from campaign.config.values import FrozenMap
from campaign.config.load import load_config, parse_config
from campaign.errors import CampaignError, ConfigError, DataError
from drivers.base import ConnectionLost


ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"
REFERENCE = CONFIGS / "irb2600.yaml"
SHIPPED = ["irb2600.yaml", "ur10.yaml", "irb4600.yaml"]


def reference_text() -> str:
    return REFERENCE.read_text(encoding="utf-8")


def reference_dict() -> dict[str, Any]:
    """A fresh copy of the reference config as a dict (parsed once: most bad-config cases edit it)."""
    return copy.deepcopy(_reference_data(reference_text()))


@functools.lru_cache(maxsize=1)
def _reference_data(text: str) -> dict[str, Any]:
    return yaml.safe_load(text)


# --------------------------------------------------------------------------- good configs


@pytest.mark.unit
@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_configs_load(name: str) -> None:
    cfg = load_config(CONFIGS / name)
    assert cfg.name == Path(name).stem
    assert cfg.robot.n_joints == 6
    assert len(cfg.plan.q_ref_deg) == cfg.robot.n_joints
    assert cfg.sha256 == hashlib.sha256((CONFIGS / name).read_bytes()).hexdigest()


@pytest.mark.unit
@pytest.mark.parametrize("name", SHIPPED)
def test_to_dict_is_json_and_reloads_to_the_same_config(name: str, tmp_path: Path) -> None:
    cfg = load_config(CONFIGS / name)
    plain = json.loads(json.dumps(cfg.to_dict()))
    assert plain["robot"]["joints"][1]["a_mm"] == cfg.robot.joints[1].a_mm
    assert plain.pop("sha256") == cfg.sha256
    assert plain.pop("source_path") == str(CONFIGS / name)
    again = tmp_path / name
    again.write_text(yaml.safe_dump(plain), encoding="utf-8")
    reloaded = load_config(again)
    assert dataclasses.replace(reloaded, source_path=cfg.source_path, sha256=cfg.sha256) == cfg


@pytest.mark.unit
def test_reference_values_are_typed_floats_and_tuples() -> None:
    cfg = load_config(REFERENCE)
    assert cfg.robot.joints[1].theta_deg == -90.0
    assert isinstance(cfg.robot.joints[0].a_mm, float)
    assert cfg.robot.hayati_joints == (2,)
    assert cfg.tool.p_flange_smr_mm == (0.0, 0.0, 39.4)
    assert cfg.plan.grid.step_mm == 200.0
    assert cfg.tracker.measurement.samples == 5 and isinstance(cfg.tracker.measurement.samples, int)
    assert cfg.calibration.ridge_mu == pytest.approx(1e-6)
    assert cfg.simulation.T_tracker_base[3] == (0.0, 0.0, 0.0, 1.0)
    assert [e.name for e in cfg.simulation.effects] == ["joint_compliance", "gear_cyclic"]     # the demo cell
    assert cfg.tool.payload_kg == 3.0 and cfg.plan.order == "random" and len(cfg.plan.nests.points) == 3
    assert cfg.output.dir == "runs"


@pytest.mark.unit
def test_config_is_frozen_and_hashable() -> None:
    cfg = load_config(REFERENCE)
    assert hash(cfg) == hash(load_config(REFERENCE))
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.name = "other"  # type: ignore[misc]


@pytest.mark.unit
def test_sha256_changes_when_the_file_changes(tmp_path: Path) -> None:
    path = tmp_path / "cell.yaml"
    path.write_text(reference_text(), encoding="utf-8")
    before = load_config(path)
    path.write_text(reference_text() + "\n# edited\n", encoding="utf-8")
    after = load_config(path)
    assert before.sha256 != after.sha256
    assert after.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    assert dataclasses.replace(after, sha256=before.sha256) == before


def minimal_dict() -> dict[str, Any]:
    ref = reference_dict()
    return {
        "name": "minimal",
        "robot": {k: ref["robot"][k] for k in ("model", "url", "convention", "joints")},
        "tool": {"p_flange_smr_mm": [0, 0, 40]},
        "tracker": {
            "url": "tracker+socket://127.0.0.1:7000",
            "position_in_base_mm": [4000, 0, 1000],
            "uncertainty": {k: v for k, v in ref["tracker"]["uncertainty"].items() if k != "coverage_k"},
        },
        "plan": {
            "grid": {"center_mm": [1000, 0, 1000], "size_mm": [400, 400, 400], "step_mm": 200},
            "tool_direction": [1, 0, 0],
            "q_ref_deg": [0, 0, 0, 0, 30, 0],
        },
    }


@pytest.mark.unit
def test_tracker_uncertainty_is_robocals_model_with_the_file_terms(tmp_path: Path) -> None:
    """One TrackerUncertainty: the config section is robocal's class, carrying the YAML terms (not its defaults)."""
    from robocal.measure.noise import TrackerUncertainty

    terms = {"transverse_a_um": 20.0, "transverse_b_um_per_m": 8.0, "range_a_um": 12.0, "range_b_um_per_m": 0.5,
             "coverage_k": 3.0}
    data = minimal_dict()
    data["tracker"]["uncertainty"] = terms
    path = tmp_path / "u.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    u = load_config(path).tracker.uncertainty
    assert type(u) is TrackerUncertainty and u != TrackerUncertainty()
    assert {k: getattr(u, k) for k in terms} == terms
    u_r, u_t = u.sigmas_mm(2000.0)
    assert (u_r, u_t) == pytest.approx(((12.0 + 2 * 0.5) / 3.0 / 1000.0, (20.0 + 2 * 8.0) / 3.0 / 1000.0))


@pytest.mark.unit
def test_minimal_config_takes_documented_defaults(tmp_path: Path) -> None:
    path = tmp_path / "minimal.yaml"
    path.write_text(yaml.safe_dump(minimal_dict()), encoding="utf-8")
    cfg = load_config(path)
    assert cfg.robot.options == {} and cfg.robot.hayati_joints == ()
    assert cfg.tracker.model == "" and cfg.tracker.uncertainty.coverage_k == 2.0
    assert cfg.tracker.measurement.samples == 5 and cfg.tracker.measurement.retries == 3
    assert cfg.plan.check_poses.count == 0 and cfg.plan.test.count == 50
    assert cfg.calibration.method == "lm" and cfg.calibration.weights == "igg3"
    assert cfg.calibration.outliers == "local" and cfg.calibration.effects == "auto"
    assert cfg.calibration.residual == "auto" and cfg.calibration.cv_folds == 5
    assert cfg.simulation.effects == () and cfg.simulation.faults.beam_break_probability == 0.0
    assert cfg.simulation.p_flange_smr_mm == cfg.tool.p_flange_smr_mm
    assert cfg.simulation.T_tracker_base[0] == (1.0, 0.0, 0.0, -4000.0)
    assert cfg.output.dir == "runs"


@pytest.mark.unit
def test_effects_and_options_are_frozen_mappings(tmp_path: Path) -> None:
    data = reference_dict()
    data["simulation"]["effects"] = [
        "backlash",
        {"name": "gear_cyclic", "scale": 0.5, "params": {"harmonics": [1, 2], "joint": 3}},
    ]
    data["robot"]["url"] = "abb-rws://192.168.125.1"      # driver options are checked by the driver (issue 12)
    data["robot"]["options"] = {"task": "T_ROB1", "credentials": {"use_default": True}}
    path = tmp_path / "fx.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    cfg = load_config(path)
    assert cfg.simulation.effects[0] == EffectSpec("backlash", 1.0, FrozenMap())
    gear = cfg.simulation.effects[1]
    assert gear.scale == 0.5 and gear.params["harmonics"] == (1, 2) and gear.params["joint"] == 3
    assert cfg.robot.options["credentials"]["use_default"] is True
    hash(cfg)
    assert cfg.to_dict()["simulation"]["effects"][1]["params"] == {"harmonics": [1, 2], "joint": 3}


@pytest.mark.unit
def test_parse_config_from_bytes() -> None:
    cfg = parse_config(REFERENCE.read_bytes(), "inline.yaml")
    assert cfg.source_path == "inline.yaml" and cfg.name == "irb2600"


# --------------------------------------------------------------------------- bad configs

Maker = Callable[[], str]


def edit(fn: Callable[[dict[str, Any]], Any]) -> Maker:
    """Text maker: the reference config as a dict, mutated by ``fn``."""

    def make() -> str:
        data = copy.deepcopy(reference_dict())
        fn(data)
        return yaml.safe_dump(data, sort_keys=False)

    return make


def text(fn: Callable[[str], str]) -> Maker:
    """Text maker: the reference YAML text, rewritten by ``fn``."""
    return lambda: fn(reference_text())


def sets(path: str, value: Any) -> Maker:
    """Set a dotted path (``a.b[2].c``) in the reference dict."""

    def apply(data: dict[str, Any]) -> None:
        *parents, last = _split(path)
        node: Any = data
        for key in parents:
            node = node[key]
        node[last] = value

    return edit(apply)


def deletes(path: str) -> Maker:
    def apply(data: dict[str, Any]) -> None:
        *parents, last = _split(path)
        node: Any = data
        for key in parents:
            node = node[key]
        del node[last]

    return edit(apply)


def _split(path: str) -> list[str | int]:
    keys: list[str | int] = []
    for part in path.split("."):
        name, *indices = part.replace("]", "").split("[")
        keys.append(name)
        keys.extend(int(i) for i in indices)
    return keys


class Bad(NamedTuple):
    make: Maker
    expect: tuple[str, ...]  # substrings of the one-line error (key path first)


def _swap_limits(data: dict[str, Any]) -> None:
    joint = data["robot"]["joints"][1]
    joint["q_min_deg"], joint["q_max_deg"] = joint["q_max_deg"], joint["q_min_deg"]


def _reflect(data: dict[str, Any]) -> None:
    for row in data["simulation"]["T_tracker_base"][:3]:
        row[2] = -row[2]


def _thirteen_joints(data: dict[str, Any]) -> None:
    data["robot"]["joints"] = data["robot"]["joints"] * 2 + data["robot"]["joints"][:1]


BAD: dict[str, Bad] = {
    "missing_step": Bad(deletes("plan.grid.step_mm"), ("plan.grid", "missing required key 'step_mm'")),
    "missing_tracker_url": Bad(deletes("tracker.url"), ("tracker", "missing required key 'url'")),
    "missing_name": Bad(deletes("name"), ("missing required key 'name'",)),
    "missing_plan": Bad(deletes("plan"), ("missing required key 'plan'",)),
    "missing_uncertainty_term": Bad(deletes("tracker.uncertainty.range_a_um"), ("tracker.uncertainty", "'range_a_um'")),
    "string_as_number": Bad(sets("plan.grid.step_mm", "abc"), ("plan.grid.step_mm", "expected a positive number, got 'abc'")),
    "negative_step": Bad(sets("plan.grid.step_mm", -200), ("plan.grid.step_mm", "expected a positive number, got -200")),
    "zero_samples": Bad(sets("tracker.measurement.samples", 0), ("tracker.measurement.samples", ">= 1")),
    "float_retries": Bad(sets("tracker.measurement.retries", 2.5), ("tracker.measurement.retries", "integer")),
    "negative_retries": Bad(sets("tracker.measurement.retries", -1), ("tracker.measurement.retries",)),
    "zero_timeout": Bad(sets("tracker.measurement.timeout_s", 0), ("tracker.measurement.timeout_s", "positive")),
    "negative_test_count": Bad(sets("plan.test.count", -5), ("plan.test.count",)),
    "bool_as_number": Bad(sets("robot.repeatability_mm", True), ("robot.repeatability_mm", "got true")),
    "bool_as_integer": Bad(sets("tracker.measurement.samples", True), ("tracker.measurement.samples", "got true")),
    "exponent_text": Bad(sets("calibration.ridge_mu", "1e-6"), ("calibration.ridge_mu", "1.0e-6")),
    "unknown_top_key": Bad(sets("colour", "red"), ("colour", "unknown key (expected one of:", "robot")),
    "unknown_nested_key": Bad(sets("robot.joints[2].foo", 1), ("robot.joints[2].foo", "unknown key", "a_mm")),
    "typo_key": Bad(text(lambda t: t.replace("step_mm: 200", "step_m: 200")), ("plan.grid.step_m", "unknown key")),
    "unknown_robot_driver": Bad(
        sets("robot.url", "foo://1.2.3.4"),
        ("robot.url", "unknown driver 'foo' (expected one of: abb-rws, mock, ur-rtde)"),
    ),
    "unknown_tracker_driver": Bad(sets("tracker.url", "telnet://10.0.0.2"), ("tracker.url", "unknown driver 'telnet'")),
    "url_without_scheme": Bad(sets("robot.url", "192.168.125.1"), ("robot.url", "driver URL")),
    "box_outside_reach": Bad(
        sets("plan.grid.center_mm", [2500, 0, 1000]),
        ("plan.grid.center_mm", "box corner (2900, 800, 1600) mm is outside the robot's reach (max 2329.4 mm"),
    ),
    "malformed_yaml": Bad(text(lambda t: t.replace("step_mm: 200", "step_mm: [200")), ("line", "column", "malformed YAML")),
    "bad_indentation": Bad(text(lambda t: t.replace("  step_mm: 200", "      step_mm: 200", 1)), ("malformed YAML",)),
    "duplicate_key": Bad(
        text(lambda t: t.replace("    step_mm: 200", "    step_mm: 200\n    step_mm: 100")),
        ("line", "malformed YAML: duplicate key 'step_mm'"),
    ),
    "empty_file": Bad(lambda: "", ("empty config file",)),
    "comments_only": Bad(lambda: "# nothing here\n", ("empty config file",)),
    "top_level_list": Bad(lambda: "- name: irb2600\n- robot: {}\n", ("top level must be a mapping", "got a list")),
    "top_level_scalar": Bad(lambda: "just text\n", ("top level must be a mapping",)),
    "section_not_mapping": Bad(sets("tracker.uncertainty", 5), ("tracker.uncertainty", "expected a mapping, got 5")),
    "wrong_length_vector": Bad(
        sets("tool.p_flange_smr_mm", [0.0, 39.4]), ("tool.p_flange_smr_mm", "expected a list of 3 numbers, got 2")
    ),
    "vector_element_type": Bad(sets("plan.grid.center_mm", [1050, "x", 1000]), ("plan.grid.center_mm[1]", "got 'x'")),
    "non_positive_size": Bad(sets("plan.grid.size_mm", [800, 0, 1200]), ("plan.grid.size_mm[1]", "positive")),
    "q_min_ge_q_max": Bad(edit(_swap_limits), ("robot.joints[1].q_max_deg", "q_min_deg = 155")),
    "q_ref_outside_limits": Bad(sets("plan.q_ref_deg[2]", 100), ("plan.q_ref_deg[2]", "outside joint 3 limits [-180, 75]")),
    "q_ref_wrong_length": Bad(sets("plan.q_ref_deg", [0, 20, -10, 0, 80]), ("plan.q_ref_deg", "list of 6 numbers, got 5")),
    "hayati_out_of_range": Bad(sets("robot.hayati_joints", [7]), ("robot.hayati_joints[0]", "in [1, 6]")),
    "hayati_zero": Bad(sets("robot.hayati_joints", [0]), ("robot.hayati_joints[0]",)),
    "no_joints": Bad(sets("robot.joints", []), ("robot.joints", "1 to 12", "got 0")),
    "too_many_joints": Bad(edit(_thirteen_joints), ("robot.joints", "got 13")),
    "bad_convention": Bad(sets("robot.convention", "craig"), ("robot.convention", "dh, mdh")),
    "zero_tool_direction": Bad(sets("plan.tool_direction", [0, 0, 0]), ("plan.tool_direction", "non-zero")),
    "non_orthonormal_T": Bad(sets("simulation.T_tracker_base[0][0]", 0.9), ("simulation.T_tracker_base", "orthonormal")),
    "reflection_T": Bad(edit(_reflect), ("simulation.T_tracker_base", "det +1")),
    "T_last_row": Bad(sets("simulation.T_tracker_base[3]", [0, 0, 1, 1]), ("simulation.T_tracker_base[3]", "[0, 0, 0, 1]")),
    "T_wrong_shape": Bad(sets("simulation.T_tracker_base", [[1, 0, 0], [0, 1, 0], [0, 0, 1]]), ("simulation.T_tracker_base", "4x4")),
    "unknown_effect": Bad(sets("simulation.effects", [{"name": "wobble"}]), ("simulation.effects[0].name", "joint_compliance")),
    "duplicate_effect": Bad(sets("simulation.effects", ["backlash", "backlash"]), ("simulation.effects[1].name", "duplicate")),
    "probability_above_one": Bad(
        sets("simulation.faults.beam_break_probability", 1.5),
        ("simulation.faults.beam_break_probability", "in [0, 1], got 1.5"),
    ),
    "k0_ge_k1": Bad(sets("calibration.k0", 3.0), ("calibration.k1", "> k0 = 3")),
    "nan_value": Bad(sets("robot.joints[0].a_mm", math.nan), ("robot.joints[0].a_mm", "finite", "nan")),
    "inf_value": Bad(sets("plan.grid.size_mm[1]", math.inf), ("plan.grid.size_mm[1]", "finite", "inf")),
    "unknown_calibration_method": Bad(sets("calibration.method", "magic"), ("calibration.method", "robust_ridge, lm", "'magic'")),
    "unknown_weights": Bad(sets("calibration.weights", "tukey"), ("calibration.weights",)),
    "unknown_residual": Bad(sets("calibration.residual", "kriging"), ("calibration.residual",)),
    "bad_name": Bad(sets("name", "my campaign"), ("name", "run directories")),
    "options_not_mapping": Bad(sets("robot.options", [1, 2]), ("robot.options", "expected a mapping")),
    "options_non_string_key": Bad(text(lambda t: t.replace("  options: {}", "  options: {1: a}", 1)), ("robot.options", "string keys")),
}


@pytest.fixture(params=sorted(BAD), ids=sorted(BAD))
def bad_config(request: pytest.FixtureRequest, tmp_path: Path) -> tuple[Path, Bad]:
    case = BAD[request.param]
    path = tmp_path / f"{request.param}.yaml"
    path.write_text(case.make(), encoding="utf-8")
    return path, case


@pytest.mark.unit
def test_bad_config_raises_one_line_error(bad_config: tuple[Path, Bad]) -> None:
    path, case = bad_config
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    for part in case.expect:
        assert part in message, f"{part!r} not in {message!r}"
    assert isinstance(info.value, ValueError) and isinstance(info.value, CampaignError)


@pytest.mark.unit
def test_bad_config_cli_exit_2(bad_config: tuple[Path, Bad], capsys: pytest.CaptureFixture[str]) -> None:
    path, case = bad_config
    assert main(["validate", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err
    assert str(path) in err and case.expect[0] in err


@pytest.mark.unit
def test_key_path_attribute() -> None:
    data = reference_dict()
    data["robot"]["joints"][2]["a_mm"] = "long"
    with pytest.raises(ConfigError) as info:
        parse_config(yaml.safe_dump(data).encode(), "x.yaml")
    err = info.value
    assert (err.file, err.key_path) == ("x.yaml", "robot.joints[2].a_mm")
    assert err.message == "expected a number, got 'long'"


@pytest.mark.unit
def test_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError, match="file not found"):
        load_config(path)
    assert main(["validate", str(path)]) == 2
    assert "file not found" in capsys.readouterr().err


@pytest.mark.unit
def test_directory_instead_of_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="directory"):
        load_config(tmp_path)


@pytest.mark.unit
def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes(b"name: \xff\xfe\n")
    with pytest.raises(ConfigError, match="UTF-8"):
        load_config(path)


# --------------------------------------------------------------------------- errors


@pytest.mark.unit
def test_error_formats() -> None:
    err = ConfigError("configs/irb2600.yaml", "plan.grid.step_mm", "expected a positive number, got -200")
    assert str(err) == "configs/irb2600.yaml: plan.grid.step_mm: expected a positive number, got -200"
    assert str(ConfigError("f.yaml", "", "file not found")) == "f.yaml: file not found"
    assert str(ConfigError.malformed_yaml("f.yaml", 3, 7, "bad\nthing")) == "f.yaml: line 3, column 7: malformed YAML: bad thing"
    assert str(DataError("m.csv", "expected a number, got 'x'", line=12, column=3)) == (
        "m.csv: line 12, column 3: expected a number, got 'x'"
    )
    assert str(DataError("m.csv", "no header")) == "m.csv: no header"
    for exc in (err, DataError("m.csv", "x", 1, 2)):
        assert str(pickle.loads(pickle.dumps(exc))) == str(exc)


# --------------------------------------------------------------------------- CLI


@pytest.mark.unit
@pytest.mark.parametrize("name", SHIPPED)
def test_validate_good_config(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(CONFIGS / name)]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    lines = out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("OK ")
    assert Path(name).stem in lines[0] and "6 joints" in lines[0] and "mock://robot" in lines[0]


def _register(monkeypatch: pytest.MonkeyPatch, exc: BaseException) -> None:
    def handler(args: Any) -> int:
        raise exc

    monkeypatch.setitem(cli.COMMANDS, "boom", cli.Command("boom", "raise", lambda p: None, handler))


@pytest.mark.parametrize(
    ("exc", "code"),
    [
        (ConnectionLost("tracker 10.0.0.2:7000: connection lost"), 1),
        (DataError("log.csv", "bad value", line=4, column=2), 2),
        (KeyboardInterrupt(), 130),
    ],
)
@pytest.mark.unit
def test_cli_error_exit_codes(
    exc: BaseException, code: int, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _register(monkeypatch, exc)
    assert main(["boom"]) == code
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.unit
def test_cli_usage_errors_return_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    assert main(["no-such-command"]) == 2
    assert main(["--help"]) == 0
    capsys.readouterr()


@pytest.mark.system
def test_python_m_campaign(tmp_path: Path) -> None:
    ok = subprocess.run(
        [sys.executable, "-m", "campaign", "validate", str(REFERENCE)], capture_output=True, text=True, cwd=ROOT
    )
    assert ok.returncode == 0 and ok.stdout.startswith("OK ")
    bad = tmp_path / "bad.yaml"
    bad.write_text("- 1\n", encoding="utf-8")
    failed = subprocess.run(
        [sys.executable, "-m", "campaign", "validate", str(bad)], capture_output=True, text=True, cwd=ROOT
    )
    assert failed.returncode == 2 and "Traceback" not in failed.stderr
    assert len(failed.stderr.strip().splitlines()) == 1
