"""Every CSV the controller writes is spreadsheet-safe (issue 36): the writers are enumerated here, each is made to
write ids that a spreadsheet would run as formulas, and no cell of any file is one. A structure check fails when a
module starts writing CSV text outside the enumerated writers (they all use ``campaign.io.csv_cells``)."""
from __future__ import annotations

import csv
import io
import re
from pathlib import Path

import pytest

from campaign.io.csv_cells import FORMULA_START
from tests.campaign.helpers import ROOT, small_config
from tests.campaign.hostile import cli

FORMULA_IDS = ["=cmd|' /C calc'!A0", "+SUM(A1)", "-HYPERLINK(1)", "@SUM(1)", "\tTAB", "=1+1"]

# module -> the CSV files it writes (each produced below); modules that join text with commas for another purpose
WRITERS = {
    "campaign/plan/points.py": ("plan.csv",),
    "campaign/data/interchange_csv.py": ("data.csv", "select --out", "import --out"),
    "campaign/calibrate/report_points.py": ("points.csv",),
    "campaign/report/export.py": ("dh.csv",),
    "campaign/correct/target_csv.py": ("targets.csv", "rejected.csv"),
}
NOT_CSV = {
    "campaign/correct/ur_program.py": "URScript lists and poses",
    "drivers/abb_rws.py": "RAPID values and RWS form fields",
}
WRITES = re.compile(r"atomic_write|write_text|open\(")
JOINS = re.compile(r'",".join\(|csv\.writer|render_rows')


@pytest.mark.unit
def test_every_module_that_writes_csv_text_is_an_enumerated_writer():
    found = {str(p.relative_to(ROOT)) for pkg in ("campaign", "drivers", "robocal") for p in (ROOT / pkg).rglob("*.py")
             if p.name != "__init__.py"                     # a room's door: names, no code
             and WRITES.search(p.read_text()) and JOINS.search(p.read_text())}
    assert found == set(WRITERS) | set(NOT_CSV), found ^ (set(WRITERS) | set(NOT_CSV))


def formula_cells(path: Path) -> list[str]:
    """Cells of a CSV file that a spreadsheet would evaluate (text starting with = + - @ tab CR, not a number)."""
    bad = []
    for row in csv.reader(io.StringIO(path.read_text(encoding="utf-8"))):
        for cell in row:
            if cell[:1] in FORMULA_START:
                try:
                    float(cell)
                except ValueError:
                    bad.append(cell)
    return bad


@pytest.mark.system
def test_no_writer_writes_a_formula_cell(tmp_path, capsys, monkeypatch):
    import campaign.calibrate.report_points as report_points

    cfg = small_config(tmp_path)
    assert cli(capsys, "run", cfg, "--out", tmp_path / "run")[0] == 0
    rows = list(csv.reader((tmp_path / "run" / "data.csv").read_text().splitlines()))
    for r, pid in zip([r for r in rows[1:] if r[1] == "calib"], FORMULA_IDS):
        r[0] = pid
    src = tmp_path / "formulas.csv"
    with open(src, "w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows(rows)
    monkeypatch.setattr(report_points, "POINTS_INLINE_MAX", 2)          # points.csv beside report.json
    written = {}
    assert cli(capsys, "reprocess", src, "--config", cfg, "--out", tmp_path / "re")[0] == 0
    written["points.csv"] = tmp_path / "re" / "points.csv"
    written["data.csv"] = tmp_path / "run" / "data.csv"
    assert cli(capsys, "plan", cfg, "--csv", tmp_path / "plan.csv")[0] == 0
    written["plan.csv"] = tmp_path / "plan.csv"
    code, _, err = cli(capsys, "select", src, "--config", cfg, "--points", "30", "--out", tmp_path / "sel.csv")
    assert code == 0, err
    written["select --out"] = tmp_path / "sel.csv"
    assert cli(capsys, "export", tmp_path / "run" / "model.json", "--dh-csv", tmp_path / "dh.csv")[0] == 0
    written["dh.csv"] = tmp_path / "dh.csv"
    targets = tmp_path / "targets_in.csv"
    targets.write_text("target_id,x,y,z\n" + "".join(f'"{pid}",{900 + 10 * i},0,1000\n'
                                                      for i, pid in enumerate(FORMULA_IDS))
                       + '"=FAR()",9000,0,1000\n')
    code, _, err = cli(capsys, "correct", "--config", cfg, "--model", tmp_path / "run" / "model.json", "--targets",
                       targets, "--out", tmp_path / "corr", "--format", "csv")
    assert code == 0, err
    written["targets.csv"] = tmp_path / "corr" / "targets.csv"
    written["rejected.csv"] = tmp_path / "corr" / "rejected.csv"
    ur5 = ROOT / "tests" / "data" / "serial_robots_datasets" / "UR5"
    calib = next(p for p in sorted(ur5.rglob("*.csv")) if "calib" in p.name.lower())
    assert cli(capsys, "import", "target-dif", calib, "--out", tmp_path / "imported.csv")[0] == 0
    written["import --out"] = tmp_path / "imported.csv"
    assert set(written) == {name for names in WRITERS.values() for name in names}
    for name, path in written.items():
        assert path.is_file(), name
        assert not formula_cells(path), (name, formula_cells(path)[:5])
    ids = {r[0] for r in csv.reader(written["targets.csv"].read_text().splitlines()[1:])}
    assert {"'" + pid for pid in FORMULA_IDS if pid == pid.strip()} <= ids   # neutralised, not dropped (the reader strips)
    assert "'=FAR()" in written["rejected.csv"].read_text()
