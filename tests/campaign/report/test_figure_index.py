"""Figures drawn once (campaign.report.figure_index): a report written again takes the figures whose documents are
unchanged from the figures directory, gives the page drawn afresh byte for byte, and draws again whatever changed,
was edited or is missing."""
import hashlib
import json
import shutil

import pytest

from campaign.cli import main
from tests.campaign.helpers import small_config

pytestmark = pytest.mark.system


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("figindex")
    cfg = small_config(tmp)
    assert main(["run", str(cfg), "--out", str(tmp / "run")]) == 0
    return tmp / "run"


def _drawn(monkeypatch) -> list:
    """Record every section the report draws (the names of the drawing functions called)."""
    import campaign.report.html as html
    import campaign.report.html_figures as hf

    calls = []
    for name in ("calibration_figures", "budget_figure", "verify_figure", "iso_figures"):
        monkeypatch.setattr(hf, name, (lambda f, n: lambda *a: calls.append(n) or f(*a))(getattr(hf, name), name))
    monkeypatch.setattr(html, "diagnosis_figures", (lambda f: lambda *a: calls.append("diagnosis") or f(*a))(
        html.diagnosis_figures))
    return calls


def _pngs(d):
    return {p.name: p.read_bytes() for p in sorted(d.glob("*.png"))}


def test_a_report_written_again_draws_nothing_and_is_the_page_drawn_afresh(run_dir, tmp_path, monkeypatch):
    index = json.loads((run_dir / "report_figures" / "figures.json").read_text())
    assert {"calibration", "budget"} <= set(index["sections"])
    for s in index["sections"].values():
        for f in s["figures"]:
            assert hashlib.sha256((run_dir / "report_figures" / f"{f['name']}.png").read_bytes()).hexdigest() == \
                f["sha256"]
    calls = _drawn(monkeypatch)
    assert main(["report", str(run_dir), "--out", str(tmp_path / "again.html")]) == 0
    assert calls == []
    monkeypatch.undo()
    bare = tmp_path / "bare" / "run"                                  # same name: the page's title names it
    shutil.copytree(run_dir, bare)
    (bare / "report_figures" / "figures.json").unlink()
    calls = _drawn(monkeypatch)
    assert main(["report", str(bare), "--out", str(tmp_path / "fresh.html")]) == 0
    assert "calibration_figures" in calls and "budget_figure" in calls
    again = (tmp_path / "again.html").read_text().replace("again_figures", "fresh_figures")
    assert again == (tmp_path / "fresh.html").read_text()
    assert _pngs(tmp_path / "again_figures") == _pngs(tmp_path / "fresh_figures") == _pngs(run_dir / "report_figures")


def test_a_changed_document_redraws_its_section_and_only_it(run_dir, tmp_path, monkeypatch):
    work = tmp_path / "run"
    shutil.copytree(run_dir, work)
    doc = json.loads((work / "report.json").read_text())
    for stage, rows in doc["points"]["err_base_mm"].items():          # the points' errors: the calibration figures
        doc["points"]["err_base_mm"][stage] = [[None if v is None else 1.5 * v for v in row] for row in rows]
    (work / "report.json").write_text(json.dumps(doc))
    calls = _drawn(monkeypatch)
    assert main(["report", str(work), "--out", str(tmp_path / "changed.html")]) == 0
    assert calls == ["calibration_figures"]
    assert _pngs(tmp_path / "changed_figures") != _pngs(run_dir / "report_figures")


@pytest.mark.parametrize("damage", ["png", "index", "link"])
def test_an_edited_or_missing_figure_or_index_is_drawn_again(run_dir, tmp_path, monkeypatch, damage):
    work = tmp_path / "run"
    shutil.copytree(run_dir, work)
    figs = work / "report_figures"
    if damage == "png":
        (figs / "cdf.png").write_bytes(b"\x89PNG not the figure")
    elif damage == "index":
        (figs / "figures.json").write_text('{"format": "campaign-figures/1", "sections": [1, 2')
    else:
        (figs / "cdf.png").unlink()
        (figs / "cdf.png").symlink_to(run_dir / "report_figures" / "cdf.png")
    calls = _drawn(monkeypatch)
    assert main(["report", str(work), "--out", str(tmp_path / "out.html")]) == 0
    assert "calibration_figures" in calls and ("budget_figure" in calls) == (damage == "index")
    assert _pngs(tmp_path / "out_figures") == _pngs(run_dir / "report_figures")


def test_report_of_a_run_loads_no_scipy(run_dir, tmp_path):
    """``campaign report`` reads documents and PNG files: no scipy module (nor the calibration's numerics) loads."""
    import subprocess
    import sys

    from tests.campaign.helpers import ROOT

    probe = ("import sys\nfrom campaign.cli import main\n"
             f"assert main(['report', {str(run_dir)!r}, '--out', {str(tmp_path / 'r.html')!r}]) == 0\n"
             "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy' or m.startswith('robocal.layers')))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]", out
