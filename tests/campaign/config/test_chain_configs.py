"""Configs of chains other than 6R: the sample cells validate and reload from their dict form; a track is a
prismatic first joint with its own keys; what is refused is refused in one line at the key."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import yaml

from campaign.config.load import load_cell, load_config
from campaign.errors import ConfigError

CONFIGS = Path(__file__).resolve().parents[3] / "configs"
CHAINS = ["iiwa14.yaml", "meca500_mdh.yaml", "irb2600_track.yaml"]


@pytest.mark.unit
@pytest.mark.parametrize("name", CHAINS)
def test_chain_config_reloads_from_its_dict_form(name: str, tmp_path: Path) -> None:
    cfg = load_config(CONFIGS / name)
    plain = json.loads(json.dumps(cfg.to_dict()))
    plain.pop("sha256"), plain.pop("source_path")
    again = tmp_path / name
    again.write_text(yaml.safe_dump(plain), encoding="utf-8")
    assert dataclasses.replace(load_config(again), source_path=cfg.source_path, sha256=cfg.sha256) == cfg


@pytest.mark.unit
def test_track_is_a_prismatic_first_joint_with_its_travel_in_mm() -> None:
    cell = load_cell(CONFIGS / "irb2600_track.yaml")
    track = cell.config.robot.track
    assert track is not None and track.mechanical_unit == "TRACK_1" and (track.q_min_deg, track.q_max_deg) == (0, 6000)
    kin = cell.kinematics
    assert kin.n == 7 and kin.n_track == 1 and list(kin.track) == [0, 1, 0]
    assert cell.config.plan.track_stations == 5


def _edited(tmp_path: Path, name: str, edit) -> Path:
    doc = yaml.safe_load((CONFIGS / name).read_text())
    edit(doc)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.mark.unit
@pytest.mark.parametrize("name, edit, where, words", [
    ("irb2600_track.yaml", lambda d: d["robot"]["joints"].insert(3, d["robot"]["joints"].pop(0)),
     "robot.joints[3].type", "first joint only"),
    ("irb2600_track.yaml", lambda d: d["robot"]["joints"][0].update(axis=[0, 0, 0]), "robot.joints[0].axis",
     "non-zero"),
    ("irb2600_track.yaml", lambda d: d["robot"]["joints"][0].update(alpha_deg=90), "robot.joints[0].alpha_deg",
     "unknown key"),
    ("irb2600_track.yaml", lambda d: d["plan"].update(kind="optimal", points=90), "plan.kind", "grid"),
    ("irb2600.yaml", lambda d: d["plan"].update(track_stations=4), "plan.track_stations", "no track"),
])
def test_refusals_name_the_key(tmp_path: Path, name, edit, where, words) -> None:
    with pytest.raises(ConfigError) as err:
        load_config(_edited(tmp_path, name, edit))
    msg = str(err.value)
    assert where in msg and words in msg and "\n" not in msg
