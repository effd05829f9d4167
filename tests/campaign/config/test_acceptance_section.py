"""acceptance: {max_rms_mm, max_mm}: optional, each bound optional, positive numbers; a bad value is one line."""
import pytest
import yaml

from campaign.cli import main
from campaign.config.load import load_config
from campaign.errors import ConfigError
from tests.campaign.helpers import ROOT


def _with(tmp_path, acceptance):
    doc = yaml.safe_load((ROOT / "configs/irb2600.yaml").read_text())
    doc.pop("acceptance", None)
    if acceptance is not None:
        doc["acceptance"] = acceptance
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.mark.unit
def test_acceptance_is_optional_and_each_bound_too(tmp_path):
    assert not load_config(_with(tmp_path, None)).acceptance.configured
    a = load_config(_with(tmp_path, {"max_rms_mm": 0.05})).acceptance
    assert (a.max_rms_mm, a.max_mm, a.configured) == (0.05, None, True)
    a = load_config(_with(tmp_path, {"max_rms_mm": 0.05, "max_mm": 0.2})).acceptance
    assert (a.max_rms_mm, a.max_mm) == (0.05, 0.2)


@pytest.mark.unit
@pytest.mark.parametrize("acceptance, path", [({"max_rms_mm": -1}, "acceptance.max_rms_mm"),
                                              ({"max_mm": "big"}, "acceptance.max_mm"),
                                              ({"rms_mm": 0.1}, "acceptance.rms_mm"),
                                              ([0.1], "acceptance")])
def test_bad_acceptance_is_one_line_exit_2(tmp_path, capsys, acceptance, path):
    cfg = _with(tmp_path, acceptance)
    with pytest.raises(ConfigError) as exc:
        load_config(cfg)
    assert exc.value.key_path == path
    assert main(["validate", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert path in err and len(err.strip().splitlines()) == 1
