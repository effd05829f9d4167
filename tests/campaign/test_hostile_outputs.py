"""Hostile but realistic use (issue 25): owned outputs, secrets, terminal and spreadsheet safety, implausible data,
resume checks. One row per case; each runs the real entry point (``python -m campaign``) in a fresh directory and
must give the expected exit code, exactly one stderr line (none on a clean success, the one warning on a success
with a warning), no traceback, no pre-existing file modified (checksums), and no secret in any byte written
(stdout, stderr, every file under the directory, crash reports included: ``TMPDIR`` points into it).
"""
from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from campaign.run.output_dirs import MARKER
from campaign.run.log_reader import encode_record
from tests.campaign.helpers import read_report, small_config
from tests.campaign.hostile import SECRET, checksums, run_campaign_process, secret_hits

pytestmark = pytest.mark.system

KEEP_POINTS = 12
ESC = "\x1b"


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """One finished small run: its directory, config, data.csv rows and the lines of an interrupted copy."""
    from campaign.cli import main

    root = tmp_path_factory.mktemp("hostile-outputs")
    cfg = small_config(root)
    assert main(["run", str(cfg), "--out", str(root / "run")]) == 0
    lines = (root / "run" / "log.jsonl").read_bytes().splitlines(keepends=True)
    points = [json.loads(ln) for ln in lines[1:] if json.loads(ln)["kind"] == "point"][:KEEP_POINTS]
    first = json.loads(lines[0])["seq"] + 1
    kept = [lines[0]] + [encode_record("point", seq, r["data"]) for seq, r in enumerate(points, start=first)]
    rows = (root / "run" / "data.csv").read_text().splitlines()
    return {"root": root, "config": cfg, "run": root / "run", "rows": rows, "log": kept}


# ----------------------------------------------------------------------------------------------- set-ups

def _copy_run(w: Path, b: dict, name: str = "run") -> Path:
    shutil.copytree(b["run"], w / name)
    return w / name


def _csv(w: Path, b: dict, edit: Callable[[list[list[str]]], None], name: str = "data.csv") -> Path:
    """data.csv of the base run, edited (rows as lists of cells, header first)."""
    rows = [r.split(",") for r in b["rows"]]
    edit(rows)
    (w / name).write_text("\n".join(",".join(r) for r in rows) + "\n")
    return w / name


def _set(rows: list[list[str]], column: str, row: int, value: str) -> None:
    rows[row][rows[0].index(column)] = value


def _config(w: Path, b: dict, **changes) -> Path:
    doc = yaml.safe_load(b["config"].read_text())
    for key, value in changes.items():
        node = doc
        *parents, last = key.split(".")
        for k in parents:
            node = node.setdefault(k, {})
        node[last] = value
    doc["output"] = {"dir": str(w / "runs")}
    (w / "cfg.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return w / "cfg.yaml"


def _interrupted(w: Path, b: dict, edit: Callable[[list[bytes]], None] | None = None) -> Path:
    """A resumable copy of the first KEEP_POINTS points of the base run, its log edited (valid CRCs)."""
    run = w / "run"
    run.mkdir()
    for name in ("config.yaml", "plan.csv", MARKER):
        shutil.copy(b["run"] / name, run / name)
    lines = [bytes(x) for x in b["log"]]
    if edit:
        edit(lines)
    (run / "log.jsonl").write_bytes(b"".join(lines))
    return run


def _record(line_no: int, fn: Callable[[dict], None]) -> Callable[[list[bytes]], None]:
    def apply(lines: list[bytes]) -> None:
        rec = json.loads(lines[line_no - 1])
        fn(rec["data"])
        lines[line_no - 1] = encode_record(rec["kind"], rec["seq"], rec["data"])
    return apply


def _targets(w: Path, ids: list[str]) -> Path:
    """Targets near the base run's workspace, ids as given (the last two far out of reach: rejected, printed)."""
    xyz = ["900,0,1000", "1000,100,900", "950,50,950", "1000,0,950", "3000,0,1000", "0,3500,0"]
    (w / "targets.csv").write_text("target_id,x,y,z\n" + "".join(f"{i},{p}\n" for i, p in zip(ids, xyz)))
    return w / "targets.csv"


HOSTILE_IDS = ["[/]", "=cmd|' /C calc'!A0", "-1+2", "+5", f"[link=file:///etc/passwd]click[/link]",
               f"{ESC}]8;;http://x\a{ESC}[2Jevil"]


# ----------------------------------------------------------------------------------------------- extra checks

def _no_run_dirs(w: Path, out: str, err: str) -> None:
    assert not (w / "runs").exists(), "a run directory (or its parent) was created"


def _nothing_written(w: Path, out: str, err: str) -> None:
    assert not list((w / "dir").iterdir()) and not [p for p in w.rglob("*") if p.name.endswith(".tmp")]
    assert not (w / "dir_figures").exists()


def _terminal_safe(w: Path, out: str, err: str) -> None:
    assert ESC not in out + err and "\a" not in out + err          # escape sequences shown, never sent
    assert "\\x1b" in out and "[link=file:///etc/passwd]click[/link]" in out   # markup printed as text


def _spreadsheet_safe(w: Path, out: str, err: str) -> None:
    import csv
    rows = list(csv.reader((w / "out" / "targets.csv").read_text().splitlines()))
    ids = [r[0] for r in rows[1:]]
    assert ids == ["[/]", "'=cmd|' /C calc'!A0", "'-1+2", "+5"], ids           # numbers are not formulas
    assert any(v.startswith("-") for r in rows[1:] for v in r[1:]), "negative numbers must stay numbers"
    rejected = list(csv.reader((w / "out" / "rejected.csv").read_text().splitlines()))
    assert [r[0] for r in rejected[1:]] == HOSTILE_IDS[4:]
    from campaign.correct.target_csv import read_corrected_targets_csv
    assert [t.target_id for t in read_corrected_targets_csv(w / "out" / "targets.csv")] == HOSTILE_IDS[:4]


def _no_test_rows_reported(w: Path, out: str, err: str) -> None:
    assert "held-out test set: none" in out
    report = read_report(w / "out")
    assert report.n.test == 0 and any("no test rows" in n for n in report.plausibility.notes)
    assert "Held-out test set: none" in (w / "out" / "report.html").read_text()


def _markers(*kinds: str) -> Callable[[Path, str, str], None]:
    def check(w: Path, out: str, err: str) -> None:
        found = sorted(json.loads(p.read_text())["kind"] for p in w.rglob(MARKER))
        assert found == sorted(kinds), found
    return check


# ----------------------------------------------------------------------------------------------- the table

@dataclass(frozen=True)
class Case:
    argv: Callable[[Path, dict], list]            # set-up in the fresh directory; returns the command line
    code: int = 2
    needles: tuple[str, ...] = ()                 # in the one stderr line
    lines: int = 1                                # stderr lines (0: a clean success)
    check: Callable[[Path, str, str], None] | None = None
    may_change: tuple[str, ...] = ()              # pre-existing files the command may rewrite (--overwrite)


def _foreign_plan(w, b):
    (w / "mine").mkdir()
    (w / "mine" / "plan.csv").write_text("my,own,plan\n")
    return ["run", b["config"], "--out", w / "mine"]


def _link(link: Path, target: Path) -> Path:
    link.symlink_to(target)
    return link


def _report_existing_file(w, b):
    (w / "mine.html").write_text("<p>my page</p>\n")
    (w / "figures").mkdir()
    (w / "figures" / "cdf.png").write_bytes(b"my figure")
    return ["report", _copy_run(w, b), "--out", w / "mine.html"]


def _report_foreign_figures(w, b):
    (w / "new_figures").mkdir()
    (w / "new_figures" / "cdf.png").write_bytes(b"my figure")
    return ["report", _copy_run(w, b), "--out", w / "new.html"]


def _report_overwrite(w, b):
    (w / "mine.html").write_text("<p>my page</p>\n")
    return ["report", _copy_run(w, b), "--out", w / "mine.html", "--overwrite"]


def _report_into_dir(w, b):
    (w / "dir").mkdir()
    return ["report", _copy_run(w, b), "--out", w / "dir"]


def _reprocess_twice(w, b):
    _csv(w, b, lambda rows: None, "other.csv")
    (w / "out").mkdir()
    (w / "out" / MARKER).write_text(json.dumps({"format": "campaign-owner/1", "kind": "reprocess",
                                                 "source": str(b["run"] / "data.csv"), "created_utc": "x"}))
    (w / "out" / "model.json").write_text("{}")
    return ["reprocess", w / "other.csv", "--config", b["config"], "--out", w / "out"]


def _edited_plan(w, b):
    run = _interrupted(w, b)
    text = (run / "plan.csv").read_text().splitlines(keepends=True)
    (run / "plan.csv").write_text("".join(text[:5] + text[6:]))           # one planned point removed
    return ["run", b["config"], "--resume", run]


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


CASES: dict[str, Case] = {
    # data overwritten
    "run_into_a_directory_with_a_foreign_plan_csv": Case(_foreign_plan, needles=("not empty", "--overwrite")),
    "run_into_another_run": Case(lambda w, b: ["run", b["config"], "--out", _copy_run(w, b)],
                                 needles=("another run", "--resume")),
    "run_into_another_run_even_with_overwrite": Case(
        lambda w, b: ["run", b["config"], "--out", _copy_run(w, b), "--overwrite"], needles=("another run",)),
    "reprocess_into_an_existing_run": Case(
        lambda w, b: ["reprocess", _csv(w, b, lambda rows: None), "--config", b["config"], "--out", _copy_run(w, b)],
        needles=("run directory", "never replaces a run's model")),
    "reprocess_into_another_datasets_output": Case(_reprocess_twice, needles=("another reprocess", "--overwrite")),
    "report_out_an_existing_file": Case(_report_existing_file, needles=("mine.html", "exists", "--overwrite")),
    "report_figures_directory_with_foreign_files": Case(_report_foreign_figures,
                                                        needles=("new_figures", "not empty")),
    "report_out_a_directory": Case(_report_into_dir, needles=("is a directory",), check=_nothing_written),
    "report_overwrite_is_explicit": Case(_report_overwrite, code=0, lines=0, may_change=("mine.html",),
                                         check=_markers("run", "figures", "figures")),
    "diagnose_json_an_existing_file": Case(
        lambda w, b: ["diagnose", b["run"] / "data.csv", "--config", b["config"], "--json",
                      _write(w / "d.json", "{}")], needles=("d.json", "exists")),
    "select_out_over_a_runs_log_even_with_overwrite": Case(
        lambda w, b: ["select", _copy_run(w, b), "--config", b["config"], "--points", 40, "--out",
                      w / "run" / "log.jsonl", "--overwrite"], needles=("log.jsonl", "run directory", "never")),
    "diagnose_json_over_a_runs_model_even_with_overwrite": Case(
        lambda w, b: ["diagnose", _copy_run(w, b) / "data.csv", "--config", b["config"], "--json",
                      w / "run" / "model.json", "--overwrite"], needles=("model.json", "run directory")),
    "diagnose_html_over_a_runs_report": Case(
        lambda w, b: ["diagnose", _copy_run(w, b) / "data.csv", "--config", b["config"], "--html",
                      w / "run" / "report.html"], needles=("report.html", "run directory")),
    "export_through_a_link_to_a_runs_file": Case(
        lambda w, b: ["export", _copy_run(w, b) / "model.json", "--dh-csv", _link(w / "dh.csv", w / "run" / "data.csv"),
                      "--overwrite"], needles=("dh.csv", "run directory")),
    "correct_into_a_foreign_directory": Case(
        lambda w, b: ["correct", "--config", b["config"], "--model", b["run"] / "model.json", "--targets",
                      _targets(w, ["A", "B"]), "--out", _write(w / "out" / "notes.txt", "mine\n").parent],
        needles=("not empty", "notes.txt")),
    "export_over_an_existing_file": Case(
        lambda w, b: ["export", b["run"] / "model.json", "--urdf", _write(w / "robot.urdf", "mine\n")],
        needles=("robot.urdf", "exists")),
    "plan_csv_over_an_existing_file": Case(
        lambda w, b: ["plan", b["config"], "--csv", _write(w / "plan.csv", "mine\n")], needles=("plan.csv", "exists")),
    "name_of_300_characters_validate": Case(lambda w, b: ["validate", _config(w, b, name="n" * 300)],
                                            needles=("name", "at most")),
    "name_of_300_characters_run": Case(lambda w, b: ["run", _config(w, b, name="n" * 300)],
                                       needles=("name", "at most"), check=_no_run_dirs),
    # secrets
    "url_with_credentials_validate": Case(
        lambda w, b: ["validate", _config(w, b, **{"robot.url": f"abb-rws://calib:{SECRET}@127.0.0.1:1"})],
        needles=("robot.url", "credentials", "RWS_PASSWORD")),
    "url_with_credentials_run": Case(
        lambda w, b: ["run", _config(w, b, **{"robot.url": f"abb-rws://calib:{SECRET}@127.0.0.1:1"})],
        needles=("robot.url", "credentials"), check=_no_run_dirs),
    "url_credentials_without_a_scheme": Case(
        lambda w, b: ["validate", _config(w, b, **{"tracker.url": f"calib:{SECRET}@10.0.0.2"})],
        needles=("tracker.url", "credentials in the URL are refused")),
    # terminal and spreadsheet
    "markup_and_escapes_in_ids_on_the_terminal_and_in_csv": Case(
        lambda w, b: ["correct", "--config", b["config"], "--model", b["run"] / "model.json", "--targets",
                      _targets(w, HOSTILE_IDS), "--out", w / "out", "--format", "csv"],
        code=0, lines=0, check=lambda w, out, err: (_terminal_safe(w, out, err), _spreadsheet_safe(w, out, err))),
    "markup_and_escape_in_an_error_line": Case(
        lambda w, b: ["reprocess", _csv(w, b, lambda rows: (_set(rows, "point_id", 3, f"[/]{ESC}[2J"),
                                                            _set(rows, "point_id", 4, f"[/]{ESC}[2J"))),
                      "--config", b["config"], "--out", w / "out"],
        needles=("duplicate point_id", "[/]\\x1b[2J")),
    # implausible data
    "negative_payload_kg": Case(
        lambda w, b: ["reprocess", _csv(w, b, lambda rows: _set(rows, "payload_kg", 5, "-2.5")),
                      "--config", b["config"], "--out", w / "out"], needles=("line 6", "payload_kg", "negative")),
    "t_s_going_back": Case(
        lambda w, b: ["reprocess", _csv(w, b, lambda rows: _set(rows, "t_s", 7, "0.5")), "--config", b["config"],
                      "--out", w / "out"], needles=("line 8", "t_s", "back in time")),
    "t_s_negative": Case(
        lambda w, b: ["reprocess", _csv(w, b, lambda rows: _set(rows, "t_s", 1, "-1")), "--config", b["config"],
                      "--out", w / "out"], needles=("line 2", "t_s", "negative")),
    "no_test_rows": Case(
        lambda w, b: ["reprocess", _csv(w, b, lambda rows: [r.__setitem__(1, "calib") for r in rows[1:]
                                                            if r[1] == "test"]),
                      "--config", b["config"], "--out", w / "out"],
        code=0, needles=("warning", "no test rows"), check=_no_test_rows_reported),
    # resume
    "resume_with_an_edited_config_hash": Case(
        lambda w, b: ["run", b["config"], "--resume",
                      _interrupted(w, b, _record(1, lambda d: d.__setitem__("config_sha256", "0" * 64)))],
        needles=("not the config",)),
    "resume_with_an_edited_plan_csv": Case(_edited_plan, needles=("plan.csv", "changed since the run started")),
    "resume_q_cmd_of_the_wrong_length": Case(
        lambda w, b: ["run", b["config"], "--resume",
                      _interrupted(w, b, _record(4, lambda d: d.__setitem__("q_cmd_deg", d["q_cmd_deg"][:5])))],
        needles=("line 4", "q_cmd_deg")),
    "resume_approach_malformed": Case(
        lambda w, b: ["run", b["config"], "--resume",
                      _interrupted(w, b, _record(4, lambda d: d.__setitem__("approach", [1.0, "x"])))],
        needles=("line 4", "approach")),
}


def test_table_size():
    assert len(CASES) >= 25


@pytest.mark.parametrize("name", sorted(CASES))
def test_hostile_use(name, base, tmp_path):
    case = CASES[name]
    work = tmp_path / "w"
    work.mkdir()
    argv = case.argv(work, base)
    before = checksums(tmp_path, base["root"])
    code, out, err = run_campaign_process(argv, tmp_path)
    text = out + err
    assert "Traceback" not in text and "Exception ignored" not in text, text[-2000:]
    assert code == case.code, f"exit {code}, expected {case.code}: {err[-800:]}"
    lines = err.strip().splitlines()
    assert len(lines) == case.lines, f"{len(lines)} stderr lines, expected {case.lines}: {err[-800:]}"
    for needle in case.needles:
        assert needle in lines[0], f"{needle!r} not in {lines[0]!r}"
    after = checksums(tmp_path, base["root"])
    changed = [p for p, digest in before.items() if after.get(p) != digest and Path(p).name not in case.may_change]
    assert not changed, f"pre-existing files modified or removed: {changed[:5]}"
    hits = secret_hits(tmp_path, out, err, inputs=before)        # the inputs the set-up wrote may hold it
    assert not hits, hits
    if case.check is not None:
        case.check(work, out, err)


# ----------------------------------------------------------------------------------------------- secrets, every path

RWS_SMALL = {"plan.grid.step_mm": 600, "plan.test.count": 8, "plan.check_poses": {"count": 0, "every_n_points": 50},
             "tracker.measurement.samples": 2, "tracker.measurement.settle_s": 0.0, "calibration.residual": "none"}
RWS_OPTIONS = {"settle_s": 0.01, "poll_s": 0.005, "max_poll_rate_hz": 500}


def test_a_password_from_the_environment_is_never_written(base, tmp_path):
    """A whole run against the RWS emulator, logged in with RWS_USER/RWS_PASSWORD: no byte of any output (the
    run's config copy, log.jsonl, campaign.log, report.json, report.html, ...) holds the password."""
    from drivers.emulators.rws_server import RwsEmulator

    with RwsEmulator(2, user="calib", password=SECRET, joint_speed_deg_s=5000.0) as emu:
        cfg = _config(tmp_path, base, **RWS_SMALL, **{"robot.url": emu.url, "robot.options": RWS_OPTIONS})
        before = checksums(tmp_path)
        code, out, err = run_campaign_process(["run", cfg, "--out", tmp_path / "run"], tmp_path)
    assert code == 0, err[-800:]
    assert {"config.yaml", "log.jsonl", "campaign.log", "report.json", "report.html"} <= {
        p.name for p in (tmp_path / "run").iterdir()}
    hits = secret_hits(tmp_path, out, err, inputs=before)
    assert not hits, hits


def test_a_password_from_a_file_is_masked_in_the_crash_report(base, tmp_path):
    """Credentials from options.credentials.file, then an internal error whose message holds the password (the
    worst bug): exit 3, the crash report is written and names the error, the password is masked everywhere."""
    creds = tmp_path / "rws.credentials"
    creds.write_text(f"user=calib\npassword={SECRET}\n")
    creds.chmod(0o600)
    cfg = _config(tmp_path, base, **{"robot.url": "abb-rws://127.0.0.1:1",
                                     "robot.options": {"credentials": {"file": str(creds)}}})
    bug = ("import drivers.abb_rws as a\n"
           "def connect(self, *args, **kwargs):\n"
           "    raise RuntimeError('bug while logging in with ' + self.session._credentials.password)\n"
           "a.AbbRwsRobot.connect = connect\n"
           "from campaign.cli import main\n"
           "main()\n")
    before = checksums(tmp_path)
    code, out, err = run_campaign_process(["run", cfg, "--out", tmp_path / "run"], tmp_path, code=bug,
                                          env={"RWS_PASSWORD": ""})
    assert code == 3 and len(err.strip().splitlines()) == 1 and "crash report" in err, err
    report = Path(err.strip().rsplit("crash report ", 1)[1])
    assert report.is_file() and "bug while logging in with ***" in report.read_text()
    hits = secret_hits(tmp_path, out, err, inputs=before)
    assert not hits, hits
