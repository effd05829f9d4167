"""What a new user hits at once: ``campaign --version``, and the import command that configs/ur5.yaml's comment
gives (it runs as written, from the repository's root)."""
from __future__ import annotations

import re
import shlex
from importlib.metadata import version

import pytest

from campaign.cli import main
from tests.campaign.helpers import ROOT
from tests.campaign.hostile import run_campaign_process


@pytest.mark.system
def test_version_prints_the_installed_version(tmp_path):
    code, out, err = run_campaign_process(["--version"], tmp_path)
    assert (code, out, err) == (0, f"campaign {version('robot-accuracy-campaign')}\n", "")


@pytest.mark.unit
def test_the_ur5_config_comment_gives_commands_that_run(tmp_path, monkeypatch, capsys):
    comments = " ".join(line.lstrip("# ") for line in (ROOT / "configs" / "ur5.yaml").read_text().splitlines()
                        if line.startswith("#"))
    commands = [shlex.split(c) for c in re.findall(r"`(campaign [^`]+)`", comments)]
    assert [c[1] for c in commands] == ["import", "reprocess"], commands
    monkeypatch.chdir(ROOT)                                   # "from the repository's root"
    importing = commands[0][1:]
    importing[importing.index("--out") + 1] = str(tmp_path / "data.csv")
    assert main(importing) == 0, capsys.readouterr().err
    assert "1000 calib + 20 test rows" in capsys.readouterr().out
    from campaign.cli.entry import build_parser
    args = build_parser().parse_args(commands[1][1:])         # the next command parses; tests/campaign/
    assert args.config == "configs/ur5.yaml"                  # test_ur5_public.py runs it


@pytest.mark.system
def test_no_command_imports_scipy_stats():
    """scipy.stats takes about 0.45 s to import on top of what a command needs: no module of the project imports it,
    at the top or inside a function (the tests' distributions come from scipy.special, robocal.measure.stats), and
    importing every module leaves it unloaded."""
    import ast
    import subprocess
    import sys

    sources = [p for pkg in ("campaign", "robocal", "drivers") for p in sorted((ROOT / pkg).rglob("*.py"))]
    found = []
    for path in sources:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [f"{node.module}.{a.name}" for a in node.names] if isinstance(node, ast.ImportFrom) else [])
            found += [f"{path.relative_to(ROOT)}:{node.lineno}" for n in names if n.startswith("scipy.stats")]
    assert not found, found
    probe = ("import importlib, pkgutil, sys\n"
             "for pkg in ('campaign', 'robocal', 'drivers'):\n"
             "    for m in pkgutil.walk_packages(importlib.import_module(pkg).__path__, pkg + '.'):\n"
             "        if not m.name.endswith('__main__'):\n"
             "            importlib.import_module(m.name)\n"
             "print(sorted(m for m in sys.modules if m.startswith('scipy.stats')))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out
