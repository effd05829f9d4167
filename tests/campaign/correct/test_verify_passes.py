"""``verify`` says exactly what it measured (issue 12), on the shipped UR10 and IRB 4600 cells: per pass the
corrected and held points (with reasons), and the figures over corrected points within 1.3 x the noise floor."""

import numpy as np

import pytest

from campaign.cli import main
from tests.campaign.helpers import ROOT, read_verify


@pytest.mark.system
@pytest.mark.parametrize("name", ["ur10", "irb4600"])
def test_verify_reports_held_points_and_corrected_figures(name, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["run", str(ROOT / "configs" / f"{name}.yaml"), "--out", str(run)]) == 0
    capsys.readouterr()
    assert main(["verify", str(run)]) == 0
    table = capsys.readouterr().out
    assert "held" in table and "corrected" in table
    report = read_verify(next(run.glob("verify-*/verify.json")))
    floor, n = report.noise_floor_mm, report.n
    for p in report.passes:
        if p.stage.startswith("after"):
            continue
        assert p.n_corrected + p.n_held == n
        assert sum(p.held.values()) == (p.n_held if p.stage != "uncorrected (planned joints)" else 0)
    corrected = {p.stage: p.corrected.rms_mm / floor for p in report.passes if p.corrected}
    held = {p.stage: p.n_held for p in report.passes}
    print(f"{name}: noise floor {floor:.3f} mm; corrected RMS / floor "
          + ", ".join(f"{k} {v:.2f}" for k, v in corrected.items()) + "; held " + ", ".join(f"{k} {v}" for k, v in held.items()))
    assert all(r <= 1.3 for r in corrected.values())


@pytest.mark.unit
def test_verify_gate_holds_a_command_that_moves_the_tool_beyond_the_position_bound():
    from campaign.correct.verify import held_reasons
    q0 = np.zeros((3, 6))
    q = q0 + np.radians(0.1)                            # within the 0.5 deg joint bound
    lo, hi = np.full(6, -np.pi), np.full(6, np.pi)
    held = held_reasons(q, q0, np.radians(0.5), lo, hi, 0.5, np.array([0.2, 6.0, 4.9]), 5.0)
    assert held[0] is None and held[2] is None
    assert "max_position_correction_mm 5" in held[1]
