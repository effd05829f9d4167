"""The HTML report: written by run / reprocess / diagnose from the JSON documents, self-contained, and checked
in a real headless Chromium (no console errors, every image decodes, DOM numbers equal the JSON)."""
import json
from pathlib import Path

import pytest

from campaign.cli import main
from tests.campaign.browser import Chromium, chromium
from tests.campaign.helpers import read_report, small_config

needs_browser = pytest.mark.skipif(chromium() is None, reason="chromium not installed (.ci/run installs it)")


def _lookup(doc, key):
    node = doc
    for part in key.split("."):
        node = node[int(part)] if isinstance(node, list) else node[part]
    return node


def check_numbers(page, run_dir: Path) -> int:
    """Every tagged number: data-value is the JSON value and the text is it formatted. Returns how many."""
    docs = {"calibration": "report.json", "iso9283": "report.json", "diagnosis": "diagnosis.json"}
    cache = {}
    verify = sorted(run_dir.glob("verify-*/verify.json"))
    for n in page.numbers:
        doc_name = n["doc"]
        path = verify[int(doc_name[6:])] if doc_name.startswith("verify") else run_dir / docs[doc_name]
        doc = cache.setdefault(path, json.loads(path.read_text()))
        want = _lookup(doc, n["key"])
        if want is None:
            assert n["value"] == "null" and n["text"] == "-", n
            continue
        assert float(n["value"]) == want, n
        scale = float(n["scale"]) if n["scale"] else 1.0
        assert n["text"] == format(want * scale if scale != 1.0 else want, n["fmt"]), n
    return len(page.numbers)


def check_page(run_dir: Path, tmp_path: Path, name: str):
    html = (run_dir / "report.html").read_text()
    assert "http://" not in html and "https://" not in html          # self-contained: opens from a USB stick
    with Chromium(tmp_path / f"profile-{name}") as browser:
        page = browser.load((run_dir / "report.html").resolve().as_uri())
        shot = tmp_path / f"{name}.png"
        w, h = browser.screenshot(shot)
    assert page.errors == []
    assert page.images and all(i["complete"] and i["width"] > 0 and i["height"] > 0 for i in page.images), page.images
    assert shot.stat().st_size > 50_000 and h > 2000
    print(f"{name}: {len(page.images)} images decoded, {check_numbers(page, run_dir)} numbers equal the JSON, "
          f"screenshot {shot} ({w}x{h})")
    return page


@pytest.fixture(scope="module")
def mock_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    cfg = small_config(tmp)
    assert main(["run", str(cfg), "--out", str(tmp / "run")]) == 0
    assert main(["verify", str(tmp / "run")]) == 0                 # rewrites report.html with the verify passes
    return tmp / "run", cfg


@pytest.mark.system
def test_run_writes_report_html_and_png_figures(mock_run):
    run_dir, _ = mock_run
    html = (run_dir / "report.html").read_text()
    pngs = sorted(p.name for p in (run_dir / "report_figures").glob("*.png"))
    assert len(pngs) >= 6 and html.count("<figure") == len(pngs)
    report = read_report(run_dir)
    assert len(report.points["point_id"]) == report.n.calib + report.n.test + report.n.check
    assert "Table 3" in html and "Identifiability" in html and "Excluded points" in html


@pytest.mark.system
@needs_browser
def test_mock_run_report_in_headless_chromium(mock_run, tmp_path):
    run_dir, _ = mock_run
    page = check_page(run_dir, tmp_path, "mock-run")
    keys = {n["key"] for n in page.numbers}
    assert {f"stages.{s}.test.rms_mm" for s in ("nominal", "kinematic", "compensated")} <= keys
    assert {"noise_floor_mm", "condition_number", "residual_cv.gain"} <= keys
    assert any(n["doc"] == "verify0" and n["key"].endswith(".rms_mm") for n in page.numbers)
    assert page.figures >= 6 and "seed 000 Table 3" in page.text and "Closed-loop verification" in page.text


@pytest.mark.system
@needs_browser
def test_diagnosis_with_an_effect_in_headless_chromium(tmp_path):
    cfg = small_config(tmp_path, **{"simulation.effects": [{"name": "backlash", "scale": 1.0}]})
    run_dir = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(run_dir)]) == 0
    assert main(["diagnose", str(run_dir), "--config", str(cfg)]) == 0
    diag = json.loads((run_dir / "diagnosis.json").read_text())
    accepted = [f for f in diag["findings"] if f["accepted"]]
    assert accepted and accepted[0]["effect"] == "backlash"
    page = check_page(run_dir, tmp_path, "diagnosis")
    keys = {(n["doc"], n["key"]) for n in page.numbers}
    assert ("diagnosis", "findings.0.test_rms_after_mm") in keys and ("diagnosis", "noise_floor_mm") in keys
    assert page.figures >= 6 + 3 and "Findings" in page.text and "backlash" in page.text


@pytest.mark.system
def test_report_command_errors_are_one_line(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "no report.json" in capsys.readouterr().err
    (tmp_path / "report.json").write_text("{not json")
    assert main(["report", str(tmp_path)]) == 2
