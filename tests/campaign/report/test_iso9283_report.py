"""The ISO 9283 report (issues 24, 31): RP split into the tracker's contribution and the robot's, the verdict on
the robot's RP against the datasheet, units on every column, µm in the scatter, a 3-D scatter with equal axes and
z; terminal at 80 columns. The report is built by ``iso_report`` from simulated cycles whose robot RP is known."""
import io
from types import SimpleNamespace

import numpy as np
import pytest

from campaign.calibrate.summary import FAIL, PASS
from campaign.config.load import load_cell
from campaign.io.terminal_text import SafeConsole
from campaign.plan.iso9283 import iso_cube
from campaign.report.iso9283 import NO_SPEC, UNDECIDED, iso_report, rp_verdict
from campaign.report.terminal import render_iso
from robocal.kinematics.frames import transform_points
from robocal.iso9283 import CYCLE_ORDER, POSE_NAMES, RepeatabilitySplit, tracker_rp_mm
from robocal.measure.noise import repeatability_sigma_mm
from tests.campaign.helpers import small_config

IDENT = {"simulated_devices": ["robot", "tracker"], "config_sha256": "c" * 64, "plan_sha256": "p" * 64}


def _iso_report(tmp_path, rp_robot_mm: float, spec_mm: float, cycles: int = 30, seed: int = 3,
                tracker_um: float = 15.0) -> tuple[dict, object]:
    """The ISO report of simulated nominal cycles: robot scatter of RP ``rp_robot_mm`` (isotropic), tracker noise
    drawn from the config's own tracker model (transverse MPE ``tracker_um`` + 6 um/m) at each reading."""
    cell = load_cell(small_config(tmp_path, **{"robot.repeatability_mm": spec_mm, "tracker.uncertainty": {
        "transverse_a_um": tracker_um, "transverse_b_um_per_m": 6.0, "range_a_um": 10.0, "range_b_um_per_m": 0.3}}))
    cube = iso_cube(cell)
    rng = np.random.default_rng(seed)
    T = np.asarray(cell.config.simulation.T_tracker_base, float)
    records = []
    for c in range(cycles):
        for j in CYCLE_ORDER:
            p = transform_points(T, cube.p_base_mm[j] + 0.3 + rng.normal(0, repeatability_sigma_mm(rp_robot_mm), 3))
            p = p + np.linalg.cholesky(cell.tracker.covariance(p[None])[0]) @ rng.standard_normal(3)
            records.append(SimpleNamespace(point_id=f"N:{POSE_NAMES[j]}.c{c + 1:02d}", p_tracker_mm=tuple(p)))
    return iso_report(cell, records, cube, None, IDENT), cell


def _split(low: float, high: float) -> RepeatabilitySplit:
    return RepeatabilitySplit(0.05, 0.005, 0.03, (low + high) / 2, low, high, 2.0)


@pytest.mark.unit
def test_verdict_on_the_robot_rp_interval():
    """PASS only when every interval is at or below the datasheet, FAIL when one lies wholly above, else
    UNDECIDED (naming the poses); no datasheet value, no verdict."""
    ok, straddle, above = _split(0.01, 0.04), _split(0.035, 0.06), _split(0.041, 0.06)   # straddle: centre 0.0475
    assert rp_verdict({"nominal P1": ok, "corrected P1": ok}, 0.04).result == PASS
    v = rp_verdict({"nominal P1": ok, "nominal P2": straddle}, 0.04)
    assert (v.result, v.undecided, v.failed) == (UNDECIDED, ("nominal P2",), ())
    v = rp_verdict({"nominal P1": straddle, "corrected P4": above}, 0.04)
    assert (v.result, v.failed, v.undecided) == (FAIL, ("corrected P4",), ("nominal P1",))
    assert rp_verdict({"nominal P1": ok}, 0.0).result == NO_SPEC and rp_verdict({}, None).spec_mm is None


@pytest.mark.unit
def test_a_robot_within_its_datasheet_passes_although_the_measured_rp_exceeds_it(tmp_path):
    """Robot RP 0.020 mm, datasheet 0.040 mm, a tracker whose contribution is about 0.04 mm, 60 cycles: the
    measured RP exceeds the datasheet at every pose (the old rule failed it), the robot's RP with the tracker
    removed passes, 95 % interval included."""
    rep, cell = _iso_report(tmp_path, 0.020, 0.040, cycles=60, tracker_um=5.0)
    run = rep["runs"][0]
    robot = [pc["rp_robot_mm"] for pc in run["poses"]]
    print(f"measured RP {[round(pc['rp_mm'], 4) for pc in run['poses']]}, tracker "
          f"{[round(pc['rp_tracker_mm'], 4) for pc in run['poses']]}, robot {np.round(robot, 4).tolist()} mm")
    assert min(pc["rp_mm"] for pc in run["poses"]) > 0.040
    assert rep["summary"]["verdict"] == {"spec_mm": 0.04, "result": PASS, "failed": [], "undecided": []}
    assert np.mean(robot) == pytest.approx(0.020, abs=0.006)
    for pc in run["poses"]:
        assert pc["rp_robot_low_mm"] <= pc["rp_robot_mm"] <= pc["rp_robot_high_mm"] <= 0.040 < pc["rp_mm"]
    assert rep["summary"]["simulated_devices"] == ["robot", "tracker"] and rep["config_sha256"] == "c" * 64


@pytest.mark.unit
def test_a_robot_twice_its_datasheet_fails(tmp_path):
    rep, _ = _iso_report(tmp_path, 0.080, 0.040)
    v = rep["summary"]["verdict"]
    assert v["result"] == FAIL and v["failed"] and all(name.startswith("nominal P") for name in v["failed"])


@pytest.mark.unit
def test_the_tracker_contribution_is_the_config_tracker_at_the_pose(tmp_path):
    rep, cell = _iso_report(tmp_path, 0.020, 0.040, cycles=5)
    T = np.asarray(cell.config.simulation.T_tracker_base, float)
    for pc, p in zip(rep["runs"][0]["poses"], rep["cube"]["poses_base_mm"]):
        want = tracker_rp_mm(cell.tracker.covariance(transform_points(T, np.asarray(p))[None])[0])
        assert pc["rp_tracker_mm"] == pytest.approx(want, rel=1e-3)   # at the barycentre, 0.3 mm and noise away


@pytest.mark.unit
@pytest.mark.parametrize("rp_robot, verdict", [(0.010, "PASS"), (0.080, "FAIL")])
def test_terminal_summary_units_and_the_verdict_at_80_columns(tmp_path, rp_robot, verdict):
    rep, _ = _iso_report(tmp_path, rp_robot, 0.040, tracker_um=5.0)
    console = SafeConsole(width=80, record=True, file=io.StringIO())
    render_iso(console, rep)
    text = console.export_text()
    assert all(len(line) <= 80 for line in text.splitlines())
    assert text.startswith("SIMULATED: the robot and tracker were simulated")
    for col in ("AP (mm)", "APx (mm)", "APy (mm)", "APz (mm)", "l-bar", "S_l", "RP", "tracker", "robot, 95 %"):
        assert col in text
    flat = " ".join(text.split())
    assert f"verdict: {verdict}: the robot's RP" in flat
    assert "the datasheet RP 0.0400 mm (robot.repeatability_mm)" in flat
    pc = rep["runs"][0]["poses"][rep["runs"][0]["worst_pose"]]
    assert (f"measured {pc['rp_mm']:.4f} mm; tracker's contribution {pc['rp_tracker_mm']:.4f} mm; robot, the tracker "
            f"removed in quadrature, {pc['rp_robot_mm']:.4f} mm") in flat
    assert f"RD ±{rep['runs'][0]['distance']['rd_mm']:.4f} mm" in flat and "+-" not in flat


@pytest.mark.system
def test_html_table_units_verdict_and_3d_scatter(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from campaign.report import html_figures
    from campaign.report.html import ReportSources, render_html

    rep, _ = _iso_report(tmp_path, 0.080, 0.040)
    drawn = []
    monkeypatch.setattr(html_figures, "_png", lambda fig: drawn.append(fig) or b"png")
    figs = html_figures.iso_figures(rep)
    scatter = drawn[-1]
    axes = scatter.axes
    assert len(axes) == 5 and all(ax.name == "3d" for ax in axes)
    for ax in axes:
        lims = {ax.get_xlim(), ax.get_ylim(), ax.get_zlim()}
        assert len(lims) == 1                                    # one scale on x, y and z, and for every pose
        assert "µm" in ax.get_zlabel() and "µm" in ax.get_xlabel()
        assert ax.get_box_aspect() is not None
    assert "µm" in figs[-1].caption
    page = render_html(ReportSources("iso", iso9283=rep, documents={"iso9283": rep}),
                       {"calibration": [], "verify": [], "diagnosis": [], "iso9283": figs})
    for col in ("APx (mm)", "APy (mm)", "APz (mm)", "RP (mm)", "RP tracker (mm)", "RP robot (mm)", "n (cycles)"):
        assert f">{col}</th>" in page
    assert "verdict: FAIL: the robot&#39;s RP exceeds the datasheet RP" in page
    assert " um" not in page and "(um)" not in page


@pytest.mark.unit
def test_an_iso_report_of_an_earlier_version_still_renders(tmp_path):
    """A report.json written before the RP split (no summary, no split columns): the page says it has no summary
    and shows the measured RP."""
    from campaign.report.html import ReportSources, render_html

    rep, _ = _iso_report(tmp_path, 0.02, 0.04, cycles=5)
    old = {k: v for k, v in rep.items() if k in ("format", "config", "frame", "cube", "cycles", "payload_kg",
                                                   "noise_floor_mm", "repeatability_spec_mm")}
    old["runs"] = [{k: v for k, v in run.items() if k != "worst_pose"} | {
        "poses": [{k: v for k, v in pc.items() if not k.startswith(("rp_robot", "rp_tracker", "u_rp", "k"))}
                  for pc in run["poses"]], "rp_within_spec": False} for run in rep["runs"]]
    page = render_html(ReportSources("iso", iso9283=old, documents={"iso9283": old}),
                       {"calibration": [], "verify": [], "diagnosis": [], "iso9283": []})
    assert 'id="summary-none"' in page and "RP max" in page and ">RP (mm)</th>" in page
    assert ">RP robot (mm)</th>" not in page and 'id="traceability"' not in page
