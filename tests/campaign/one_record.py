"""Checks that every output of a calibration prints the written model's record (issue 31): each identified parameter
(value and std) in the terminal table, the HTML table, report.json, dh.csv, the RoboDK table and the URDF equals
model.json's parameter table to the printed precision, and every "taken of tried" count in the terminal and the
HTML equals report.json. Each output is parsed from its text; the URDF chain is rebuilt from its origins here
(xml + scipy, not the exporter's code) and compared with model.json's kinematics by forward kinematics."""
from __future__ import annotations

import csv
import html
import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from campaign.cli import main
from robocal.kinematics.models import Kinematics, fk

JOINT_KINDS = ("theta", "d", "a", "alpha", "beta")
DH_VALUE_COLUMNS = ("theta_deg", "d_mm", "a_mm", "alpha_deg", "beta_deg")
DH_STD_COLUMNS = ("theta_std_deg", "d_std_mm", "a_std_mm", "alpha_std_deg", "beta_std_deg")


def model_rows(out: Path) -> dict[str, dict]:
    """model.json's parameter record, by name (angles in deg)."""
    table = json.loads((out / "model.json").read_text())["parameters"]
    return {r["name"]: r for r in table["rows"]}


def _fmt(value, spec: str, none: str) -> str:
    return none if value is None else format(value, spec)


def export_all(out: Path, config: Path) -> dict[str, Path]:
    """``campaign export`` of the directory's model.json: URDF, DH CSV and RoboDK table."""
    files = {"urdf": out / "robot.urdf", "dh": out / "dh.csv", "robodk": out / "robodk.txt"}
    assert main(["export", str(out / "model.json"), "--urdf", str(files["urdf"]), "--config", str(config),
                 "--dh-csv", str(files["dh"]), "--robodk", str(files["robodk"])]) == 0
    return files


def check_report_json(out: Path) -> None:
    """report.json ``parameters`` are model.json's rows, number for number."""
    report = json.loads((out / "report.json").read_text())
    rows = model_rows(out)
    assert [p["name"] for p in report["parameters"]] == list(rows)
    for p in report["parameters"]:
        assert {k: p[k] for k in rows[p["name"]]} == rows[p["name"]], p["name"]
    assert report["parameters_fit"] == json.loads((out / "model.json").read_text())["parameters"]["fit"]


def check_terminal(text: str, out: Path) -> int:
    """The terminal's parameter table: every identified row (delta +.4f, std .4f, unit) as model.json, the
    geometry-only column as report.json ``parameters_geometry_only``; returns the rows checked."""
    rows, report = model_rows(out), json.loads((out / "report.json").read_text())
    geo = {r["name"]: r for r in report.get("parameters_geometry_only") or ()}
    seen = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("│").split("│")]
        if len(cells) >= 4 and cells[0] in rows and rows[cells[0]]["identified"]:
            seen[cells[0]] = cells
    assert set(seen) == {n for n, r in rows.items() if r["identified"]}
    for name, cells in seen.items():
        r = rows[name]
        assert cells[1:4] == [format(r["delta"], "+.4f"), format(r["std"], ".4f"), r["unit"]], (name, cells)
        assert (cells[4:] == [format(geo[name]["delta"], "+.4f")]) if geo else cells[4:] == [], (name, cells)
    return len(seen)


def _table_cells(page: str, table_id: str) -> list[list[str]]:
    body = re.search(rf'<table id="{table_id}">(.*?)</table>', page, re.S).group(1)
    text = lambda c: html.unescape(re.sub(r"<[^>]+>", "", c)).strip()  # noqa: E731
    return [[text(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", tr, re.S)]
            for tr in re.findall(r"<tr>(.*?)</tr>", body, re.S)]


def check_html(out: Path) -> int:
    """report.html's parameter table: delta and std as model.json, the geometry-only columns as report.json."""
    rows, report = model_rows(out), json.loads((out / "report.json").read_text())
    geo = {r["name"]: r for r in report.get("parameters_geometry_only") or ()}
    cells = [c for c in _table_cells((out / "report.html").read_text(), "parameters-table") if c]
    assert [c[0] for c in cells] == [n for n, r in rows.items() if r["identified"]]
    for c in cells:
        r = rows[c[0]]
        want = [format(r["delta"], "+.4f"), format(r["std"], ".4f"), r["unit"]]
        if geo:
            want += [format(geo[c[0]]["delta"], "+.4f"), format(geo[c[0]]["std"], ".4f")]
        assert c[1:] == want, (c, want)
    return len(cells)


def check_dh_csv(path: Path, out: Path) -> int:
    """dh.csv: every joint's values and std (``.9g``; empty std: not identified) as model.json; the tool row."""
    rows = model_rows(out)
    with path.open(newline="") as f:
        lines = list(csv.DictReader(f))
    checked = 0
    for line in lines[:-1]:
        j = line["joint"]
        for kind, vcol, scol in zip(JOINT_KINDS, DH_VALUE_COLUMNS, DH_STD_COLUMNS):
            r = rows.get(f"{kind}{j}")
            if r is None:                                   # beta of a joint without Hayati's beta
                assert float(line[vcol]) == 0.0 and line[scol] == ""
                continue
            assert line[vcol] == format(r["value"], ".9g") and line[scol] == _fmt(r["std"], ".9g", ""), (j, kind)
            checked += 1
    tool = lines[-1]
    for axis, vcol, scol in zip("xyz", DH_VALUE_COLUMNS, DH_STD_COLUMNS):
        r = rows[f"tool_{axis}"]
        assert tool[vcol] == format(r["value"], ".9g") and tool[scol] == _fmt(r["std"], ".9g", "")
    return checked


def check_robodk(path: Path, out: Path) -> int:
    """The RoboDK table: values (``.6f``) and std (``.6g``; ``-`` not identified) of every row as model.json (the
    DHM form takes alpha, a of the previous DH joint); the tool line."""
    rows, text = model_rows(out), path.read_text()
    lines = text.splitlines()
    header = next(ln.split() for ln in lines if ln.startswith("joint"))
    cols = header[1:(len(header) + 1) // 2]
    dhm = "converted exactly" in text
    checked = 0
    for ln in lines:
        parts = ln.split()
        if not parts or not parts[0].isdigit():
            continue
        j = int(parts[0])
        for c, value, std in zip(cols, parts[1:1 + len(cols)], parts[1 + len(cols):]):
            kind = c.split("_")[0]
            name = f"{kind}{j - 1 if dhm and kind in ('alpha', 'a') else j}"
            r = rows.get(name) if not (dhm and kind in ("alpha", "a") and j == 1) else None
            if r is None:                   # DHM row 1's alpha, a; beta of a joint without Hayati's beta
                assert float(value) == 0.0 and std == "-", (ln, name)
                continue
            assert value == format(r["value"], ".6f") and std == _fmt(r["std"], ".6g", "-"), (ln, name)
            checked += 1
    tool = re.search(r"X (\S+)\s+Y (\S+)\s+Z (\S+) mm \(std_X (\S+), std_Y (\S+), std_Z (\S+)\)", text).groups()
    for axis, value, std in zip("xyz", tool[:3], tool[3:]):
        r = rows[f"tool_{axis}"]
        assert value == format(r["value"], ".6f") and std == _fmt(r["std"], ".6g", "-")
    return checked


def _origin(el) -> np.ndarray:
    o = el.find("origin")
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [float(v) for v in o.get("rpy").split()]).as_matrix()
    T[:3, 3] = [1000.0 * float(v) for v in o.get("xyz").split()]
    return T


def check_urdf(path: Path, out: Path, n_poses: int = 200) -> float:
    """The URDF: one comment per identified parameter (value ``.6f``, delta ``+.6f``, std ``.6g``) as model.json,
    and its chain (rebuilt from the origins) against model.json's kinematics at random poses; returns the largest
    SMR position difference (mm)."""
    rows, text = model_rows(out), path.read_text()
    found = re.findall(r"<!-- parameter (\S+) (\S+) (\S+) delta (\S+) std (\S+) -->", text)
    assert [f[0] for f in found] == [n for n, r in rows.items() if r["identified"]]
    for name, value, unit, delta, std in found:
        r = rows[name]
        assert (value, unit, delta, std) == (_fmt(r["value"], ".6f", "-"), r["unit"], format(r["delta"], "+.6f"),
                                            format(r["std"], ".6g")), name
    kin = Kinematics.from_dict(json.loads((out / "model.json").read_text())["kinematics"])
    joints = {j.get("name"): j for j in ET.fromstring(text).iter("joint")}
    q = np.random.default_rng(0).uniform(np.maximum(kin.q_min_rad, -np.pi), np.minimum(kin.q_max_rad, np.pi),
                                         (n_poses, kin.n))
    worst = 0.0
    for qk in q:
        T = np.eye(4)
        for i in range(kin.n):
            Rz = np.eye(4)
            Rz[:2, :2] = [[np.cos(qk[i]), -np.sin(qk[i])], [np.sin(qk[i]), np.cos(qk[i])]]
            T = T @ _origin(joints[f"j{i + 1}"]) @ Rz
        T = T @ _origin(joints["flange_joint"]) @ _origin(joints["tool_joint"])
        ours = fk(kin, qk[None])[0] @ np.r_[kin.p_flange_smr_mm, 1.0]
        worst = max(worst, float(np.max(np.abs(T[:3, 3] - ours[:3]))))
    return worst


def check_counts(text: str, out: Path) -> tuple[int, int]:
    """Every "N of M candidates taken" in the terminal (the summary's reason, the physical-effects line) and in
    report.html (the summary's reason, the effects section) equals report.json ``effects.counts``; the terminal's
    list holds one figure per candidate tried. Returns (taken, tried)."""
    report = json.loads((out / "report.json").read_text())
    counts = report["effects"]["counts"]
    want = (counts["taken"], counts["tried"])
    sel = report["effects"]["selection"]
    assert want == (len(sel["taken"]), len({t["candidate"] for t in sel["trials"]}))
    flat = lambda s: re.sub(r"\s+", " ", s)  # noqa: E731
    page = html.unescape(re.sub(r"<[^>]+>", "", (out / "report.html").read_text()))
    for where, body, n in (("terminal", flat(text), 2), ("html", flat(page), 2)):
        got = [(int(a), int(b)) for a, b in re.findall(r"(\d+) of (\d+) candidates taken", body)]
        assert len(got) == n and set(got) == {want}, (where, got, want)
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("physical effects ("))
    block = [lines[start]] + [ln for ln in lines[start + 1:start + 40]]
    end = next(i for i, ln in enumerate(block[1:], 1) if ln.startswith((" ", "residual layer", "joints:")))
    listing = flat(" ".join(block[:end])).split("): ", 1)[1]
    assert len(re.findall(r" \d\.\d{4}(?: \(taken\))?(?:,|$)", listing)) == want[1], listing
    return want


def check_everything(text: str, out: Path, config: Path) -> dict:
    """Every output of the calibration in ``out`` against model.json; the figures it checked."""
    files = export_all(out, config)
    check_report_json(out)
    return {"terminal rows": check_terminal(text, out), "html rows": check_html(out),
            "dh.csv values": check_dh_csv(files["dh"], out), "robodk values": check_robodk(files["robodk"], out),
            "urdf chain max mm": check_urdf(files["urdf"], out), "taken, tried": check_counts(text, out)}
