"""Property test of the secrets rule (issue 36): passwords drawn from the whole printable set (seeded) in a
driver URL's user-info never reach any output, file or message of ``validate``, ``plan``, ``run``, ``reprocess``
and ``report``; every command refuses the URL with one line (exit 2) before it writes anything. In-process (the
CLI's ``main``), so that many passwords stay fast; the subprocess reproductions are in ``test_hostile_harms``."""
from __future__ import annotations

import json
import shutil
import string

import numpy as np
import pytest
import yaml

from tests.campaign.hostile import assert_one_line, cli
from tests.campaign.test_hostile_harms import few_point_doc

pytestmark = pytest.mark.system

N_PASSWORDS = 40
N_REPORTS = 4                   # report renders a page: fewer passwords, the same rule
ALPHABET = string.printable     # letters, digits, punctuation (/ # ? @ : ' " ...) and whitespace
SCHEMES = ("abb-rws://", "mock://", "ur-rtde://", "emscon://", "")


def passwords(n: int, seed: int = 20261129) -> list[str]:
    """``n`` passwords of 8 to 24 characters from the printable set, each with a character urlsplit stops at."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        chars = [ALPHABET[i] for i in rng.integers(len(ALPHABET), size=int(rng.integers(8, 25)))]
        chars.insert(int(rng.integers(len(chars) + 1)), "/#?@"[int(rng.integers(4))])
        out.append("".join(chars))
    return out


def leaks(password: str, root, *texts: str) -> list[str]:
    hits = [f"message {i}" for i, t in enumerate(texts) if password in t]
    return hits + [str(p) for p in root.rglob("*") if p.is_file() and p.name not in ("cfg.yaml", "source.yaml")
                   and password.encode() in p.read_bytes()]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    from campaign.cli import main

    root = tmp_path_factory.mktemp("secrets")
    doc = few_point_doc()
    doc["output"] = {"dir": str(root / "runs")}
    (root / "small.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    assert main(["run", str(root / "small.yaml"), "--out", str(root / "run")]) == 0
    return root / "run"


def _config(tmp_path, url: str, role: str) -> tuple:
    doc = few_point_doc()
    doc[role]["url"] = url
    doc["output"] = {"dir": str(tmp_path / "runs")}
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True))
    return cfg, doc


@pytest.mark.parametrize("k", range(N_PASSWORDS))
def test_no_byte_of_a_url_password_is_written(run_dir, tmp_path, capsys, k):
    password = passwords(N_PASSWORDS)[k]
    url = f"{SCHEMES[k % len(SCHEMES)]}calib:{password}@192.0.2.{k}"
    role = ("robot", "tracker")[k % 2]
    cfg, _ = _config(tmp_path, url, role)
    assert yaml.safe_load(cfg.read_text())[role]["url"] == url
    for argv in (["validate", cfg], ["plan", cfg], ["run", cfg, "--out", tmp_path / "run"],
                 ["reprocess", run_dir / "data.csv", "--config", cfg, "--out", tmp_path / "out"]):
        code, out, err = cli(capsys, *argv)
        assert_one_line(code, out, err, 2, f"{role}.url", "credentials in the URL are refused")
        assert not leaks(password, tmp_path, out, err), (argv[0], password)
    assert not (tmp_path / "run").exists() and not (tmp_path / "out").exists() and not (tmp_path / "runs").exists()


@pytest.mark.parametrize("k", range(N_REPORTS))
def test_report_of_a_directory_whose_report_carries_a_url_password(run_dir, tmp_path, capsys, k):
    """A report.json edited by hand: its cell's robot and tracker URLs carry a password (whitespace and quotes
    included): the HTML report writes no byte of it."""
    password = passwords(N_REPORTS, seed=7)[k]
    run = tmp_path / "run"
    shutil.copytree(run_dir, run)
    report = json.loads((run / "report.json").read_text())
    report["cell"]["robot_url"] = f"abb-rws://calib:{password}@192.0.2.1"
    report["cell"]["tracker_url"] = f"calib:{password}@192.0.2.2"
    (run / "report.json").write_text(json.dumps(report))
    code, out, err = cli(capsys, "report", run)
    assert code == 0, err
    assert "***@192.0.2.1" in (run / "report.html").read_text()
    assert not leaks(password, run / "report_figures", out, err)
    assert password.encode() not in (run / "report.html").read_bytes()
    html = (run / "report.html").read_text()
    assert password not in html and _escaped(password) not in html


def _escaped(text: str) -> str:
    from markupsafe import escape
    return str(escape(text))
