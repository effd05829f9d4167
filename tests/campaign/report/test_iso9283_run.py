"""ISO 9283 on the mock cell: plan.kind iso9283 through `campaign run`, RP against the simulator's known
repeatability, and AP before / after correction with a calibrated model (`campaign iso9283 --model`)."""
import json
import urllib.parse
from pathlib import Path

import numpy as np
import pytest

from campaign.cli import main
from campaign.config.load import load_cell
from campaign.plan.iso9283 import iso_cube
from campaign.plan.build import build_plan
from robocal.iso9283 import CYCLE_ORDER
from tests.campaign.helpers import small_config

pytestmark = pytest.mark.system


def test_plan_is_the_standard_cycle(tmp_path):
    cell = load_cell(small_config(tmp_path, **{"plan.kind": "iso9283", "plan.iso9283": {"cycles": 4}}))
    plan = build_plan(cell)
    assert len(plan.points) == 4 * 5 and {p.set for p in plan.points} == {"check"}
    assert [p.point_id for p in plan.points[:6]] == ["N:P1.c01", "N:P5.c01", "N:P4.c01", "N:P3.c01", "N:P2.c01",
                                                     "N:P1.c02"]
    cube = iso_cube(cell)
    assert cube.edge_mm == min(cell.config.plan.grid.size_mm)    # the largest cube inside the box is reachable here
    assert np.allclose([plan.points[k].p_base_mm for k in range(5)], cube.p_base_mm[list(CYCLE_ORDER)])


def test_campaign_run_with_an_iso_plan_prints_ap_and_rp(tmp_path, capsys):
    cfg = small_config(tmp_path, **{"plan.kind": "iso9283", "plan.iso9283": {"cycles": 10}})
    assert main(["run", str(cfg), "--out", str(tmp_path / "iso")]) == 0
    out = capsys.readouterr().out
    assert "ISO 9283 (nominal targets, 10 cycles" in out and "AP" in out and "RP" in out and "AD" in out
    rep = json.loads((tmp_path / "iso" / "report.json").read_text())
    assert rep["format"] == "campaign-iso9283/1" and len(rep["runs"][0]["poses"]) == 5
    html = (tmp_path / "iso" / "report.html").read_text()
    assert html.count('data-doc="iso9283"') > 5 * 6 and "ISO 9283 pose accuracy and repeatability" in html


def test_rp_agrees_with_the_simulated_repeatability(tmp_path, capsys):
    """Robot RP 0.2 mm measured with a tracker ten times better (MPE a few um): mean RP of the five poses
    within 10 % of the simulator's truth."""
    rp_true = 0.2
    cfg = small_config(tmp_path, **{"plan.kind": "iso9283", "robot.repeatability_mm": rp_true,
                                    "tracker.uncertainty": {"transverse_a_um": 2.0, "transverse_b_um_per_m": 0.5,
                                                            "range_a_um": 1.0, "range_b_um_per_m": 0.1,
                                                            "coverage_k": 2.0}})
    assert main(["run", str(cfg), "--out", str(tmp_path / "iso")]) == 0
    rep = json.loads((tmp_path / "iso" / "report.json").read_text())
    run = rep["runs"][0]
    assert run["cycles"] == 30
    rp = np.array([pc["rp_mm"] for pc in run["poses"]])
    print(f"RP per pose {np.round(rp, 4).tolist()} mm, mean {rp.mean():.4f} vs truth {rp_true} mm "
          f"({100 * (rp.mean() / rp_true - 1):+.1f} %)")
    assert abs(rp.mean() / rp_true - 1) <= 0.10


@pytest.fixture(scope="module")
def calibrated_iso(tmp_path_factory):
    """A calibration run, then `campaign iso9283 --model RUN/model.json` (30 cycles) into its default place,
    RUN/iso9283-TIMESTAMP; returns (calibration run directory, ISO run directory, ISO command's stdout)."""
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("iso")
    cfg = small_config(tmp)
    assert main(["run", str(cfg), "--out", str(tmp / "cal")]) == 0
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["iso9283", str(cfg), "--model", str(tmp / "cal" / "model.json"), "--width", "200"]) == 0
    (iso,) = sorted((tmp / "cal").glob("iso9283-*"))
    return tmp / "cal", iso, out.getvalue()


def test_ap_after_correction_is_at_the_noise_floor(calibrated_iso):
    _, iso, out = calibrated_iso
    assert "corrected targets" in out
    rep = json.loads((iso / "report.json").read_text())
    floor = rep["noise_floor_mm"]
    before, after = rep["runs"]
    assert (before["targets"], after["targets"]) == ("nominal", "corrected")
    print(f"AP max nominal {before['max_ap_mm']:.4f} mm, corrected {after['max_ap_mm']:.4f} mm, "
          f"noise floor {floor:.4f} mm (ratio {after['max_ap_mm'] / floor:.2f})")
    for run in rep["runs"]:
        pc = run["poses"][run["worst_pose"]]
        print(f"{run['targets']}: largest robot RP at {pc['pose']}: measured {pc['rp_mm']:.4f} mm, tracker "
              f"{pc['rp_tracker_mm']:.4f} mm, robot {pc['rp_robot_mm']:.4f} mm ({pc['rp_robot_low_mm']:.4f} to "
              f"{pc['rp_robot_high_mm']:.4f}); max measured RP {run['max_rp_mm']:.4f} mm")
    print(f"verdict {rep['summary']['verdict']}")
    assert before["max_ap_mm"] > 5 * floor                   # the test can fail: uncorrected AP is far above
    assert after["max_ap_mm"] <= 1.5 * floor
    assert "model" in rep["frame"]


def test_iso_report_links_its_calibration_report_both_ways(calibrated_iso):
    """The ISO run went to CAL/iso9283-*; its report names the model (sha256) and links CAL/report.html, which
    was written again and lists it; the terminal showed the SIMULATED banner first and the verdict."""
    import hashlib

    cal, iso, out = calibrated_iso
    rep = json.loads((iso / "report.json").read_text())
    assert rep["model"]["sha256"] == hashlib.sha256((cal / "model.json").read_bytes()).hexdigest()
    assert (iso / rep["model"]["calibration_report"]).resolve() == (cal / "report.html").resolve()
    assert f'href="{iso.name}/report.html"' in (cal / "report.html").read_text()
    assert out.startswith("SIMULATED: the robot and tracker were simulated") and "verdict: " in out
    assert f"calibration report of the model: {(cal / 'report.html').resolve()} (written again" in out


def test_iso_bad_model_is_a_one_line_error(tmp_path, capsys):
    cfg = small_config(tmp_path)
    (tmp_path / "m.json").write_text("{}")
    assert main(["iso9283", str(cfg), "--model", str(tmp_path / "m.json")]) == 2
    assert "not a readable calibrated model" in capsys.readouterr().err


def test_cube_stays_inside_the_envelope(tmp_path):
    env = {"name": "cell", "min_mm": [600, -500, 500], "max_mm": [1400, 500, 1500]}
    cube = iso_cube(load_cell(small_config(tmp_path, **{"plan.kind": "iso9283", "plan.envelope": env,
                                                         "plan.clearance_mm": 25.0})))
    # grid box (500..1300, -800..800, 400..1600) inside envelope - 25 mm: x 625..1300 -> edge 675 at most
    assert cube.edge_mm <= 675.0 + 1e-9
    assert np.allclose(cube.center_mm, [962.5, 0.0, 1000.0])
    assert np.all(cube.p_base_mm >= np.array(env["min_mm"]) + 25) and np.all(cube.p_base_mm <= np.array(env["max_mm"]) - 25)


def test_iso_report_in_headless_chromium(calibrated_iso, tmp_path):
    """The ISO 9283 report of a mock cell, as a browser shows it: SIMULATED banner, summary with the verdict, the
    RP line with the tracker's contribution beside the measured and the robot's RP (numbers equal report.json),
    traceability with the serials and the model, sign-off, glossary entries for AP, RP, AD and RD; the link to the
    calibration report resolves, and that page links back to this one."""
    from tests.campaign.browser import Chromium, skip_without_browser
    from tests.campaign.report.test_html import check_numbers

    if skip_without_browser():
        pytest.skip("chromium not installed (tests/run installs it)")
    cal, iso, _ = calibrated_iso
    rep = json.loads((iso / "report.json").read_text())
    probe = """(() => { const q = s => document.querySelector(s), t = s => (q(s) || {}).innerText || '';
        return {sections: [...document.querySelectorAll('section')].map(s => s.id), banner: t('#simulated-banner'),
                verdict: t('#summary-verdict'), summary: t('section#summary'), trace: t('section#traceability'),
                signoff: document.querySelectorAll('#signoff tr').length,
                link: (q('#calibration-report-link') || {}).href,
                rp: [...document.querySelectorAll('.summary-rp')].map(e => ({text: e.innerText,
                     keys: [...e.querySelectorAll('[data-key]')].map(n => n.dataset.key)})),
                terms: [...document.querySelectorAll('#glossary dt')].map(e => e.innerText),
                back: [...document.querySelectorAll('a.iso-report-link')].map(a => a.href)}; })()"""
    with Chromium(tmp_path / "profile") as browser:
        page = browser.load((iso / "report.html").resolve().as_uri())
        got = browser.evaluate(probe)
        cal_page = browser.load(got["link"])
        back = browser.evaluate(probe)["back"]
    assert page.errors == [] and cal_page.errors == []
    n_iso, n_cal = check_numbers(page, iso), check_numbers(cal_page, cal)
    assert got["sections"][0] == "summary" and got["sections"][-2:] == ["glossary", "signoff"] and "traceability" in got["sections"]
    assert got["banner"].startswith("SIMULATED: the robot and tracker were simulated")
    result = rep["summary"]["verdict"]["result"]
    assert got["verdict"].startswith(f"verdict: {result.upper()}") and "datasheet RP 0.0400 mm" in got["verdict"]
    assert len(got["rp"]) == 2                                     # nominal and corrected targets
    for line, run in zip(got["rp"], rep["runs"]):
        k = f"runs.{rep['runs'].index(run)}.poses.{run['worst_pose']}."
        assert [k + f for f in ("rp_mm", "rp_tracker_mm", "rp_robot_mm", "rp_robot_low_mm", "rp_robot_high_mm")] \
            == line["keys"]
        assert "measured" in line["text"] and "tracker's contribution" in line["text"] and "quadrature" in line["text"]
    assert "Signed at the end of this report" in got["trace"] and got["signoff"] == 4
    for role in ("robot", "tracker"):
        assert rep[f"{role}_identity"]["serial"] in got["trace"]
    assert rep["model"]["sha256"] in got["trace"] and rep["config_sha256"] in got["trace"]
    terms = {t for term in got["terms"] for t in term.split(", ")}
    assert {"AP", "RP", "AD", "RD"} <= terms
    link = Path(urllib.parse.unquote(urllib.parse.urlparse(got["link"]).path))
    assert link.resolve() == (cal / "report.html").resolve() and link.exists()
    assert back == [(iso / "report.html").resolve().as_uri()]
    print(f"ISO report: {n_iso} numbers equal report.json, verdict {result}; calibration report: {n_cal} numbers, "
          f"links back to {iso.name}")
