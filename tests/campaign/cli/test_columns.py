"""Output readable at 80 columns (issue 24): ``run``, ``diagnose`` and ``verify`` on a small mock run print no line
longer than the width and break no word across lines; ``--width N`` and the piped default (100 columns)."""
import io
import json
import os

import pytest

from campaign.cli import main
from campaign.io import terminal_text
from campaign.report.diagnosis_text import effect_label
from tests.campaign.helpers import small_config

BOX = "│┃"
PUNCTUATION = "()[],;:"


def _tokens(text: str) -> set[str]:
    """Whitespace-separated words of the output, table borders and punctuation around them removed."""
    return {w.strip(PUNCTUATION) for w in "".join(" " if c in BOX else c for c in text).split()}


def _check_lines(text: str, width: int) -> None:
    long = [line for line in text.splitlines() if len(line) > width]
    assert not long, f"{len(long)} lines over {width} columns, e.g. {long[0]!r}"
    assert "…" not in text                                  # rich's ellipsis: a cut word


def _check_words(text: str, phrases) -> None:
    """Every word of every phrase (effect names, reasons, stage names) is whole on some line."""
    shown = _tokens(text)
    broken = {w for p in phrases for w in _tokens(p) if w not in shown}
    assert not broken, f"words broken or missing: {sorted(broken)[:10]}"


@pytest.mark.system
def test_run_diagnose_and_verify_fit_80_columns_without_breaking_words(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)                             # short relative paths in the output
    monkeypatch.setenv("COLUMNS", "80")
    cfg = small_config(tmp_path)
    assert main(["run", cfg.name, "--out", "run"]) == 0
    run = capsys.readouterr()
    _check_lines(run.out + run.err, 80)
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    _check_words(run.out, [u["name"] for u in report["unidentifiable"]] + ["aliased"])
    assert "~" not in run.out

    assert main(["diagnose", "run", "--config", cfg.name]) == 0
    diag = capsys.readouterr()
    _check_lines(diag.out + diag.err, 80)
    d = json.loads((tmp_path / "run" / "diagnosis.json").read_text())
    phrases = [effect_label(f) for f in d["findings"]]                 # thermal_drift(J1,2,3 tau 1 h): whole
    phrases += [f["evidence"].get("reason", "") for f in d["findings"]]
    phrases += [u["reason"] + " " + u["remedy"] for u in d.get("undiagnosable", [])]
    _check_words(diag.out, phrases)
    notes = [line for line in diag.out.splitlines() if line.startswith("[")]
    assert len(notes) == sum(1 for f in d["findings"] if f["evidence"]) and notes[0].startswith("[1] ")

    assert main(["verify", "run"]) == 0
    ver = capsys.readouterr()
    _check_lines(ver.out + ver.err, 80)
    v = json.loads(next((tmp_path / "run").glob("verify-*/verify.json")).read_text())
    _check_words(ver.out, [p["stage"] for p in v["passes"]])

    assert main(["verify", "run", "--width", "120"]) == 0     # --width wins over COLUMNS
    wide = capsys.readouterr().out
    _check_lines(wide, 120)
    assert max(map(len, wide.splitlines())) > 80


@pytest.mark.unit
def test_width_rule(monkeypatch):
    def no_terminal(fd=0):
        raise OSError("not a terminal")

    monkeypatch.setattr(os, "get_terminal_size", no_terminal)
    monkeypatch.delenv("COLUMNS", raising=False)
    terminal_text.set_width(None)
    assert terminal_text.console_width() == terminal_text.PIPED_WIDTH == 100
    monkeypatch.setenv("COLUMNS", "72")
    assert terminal_text.console_width() == 72
    monkeypatch.setattr(os, "get_terminal_size", lambda fd=0: os.terminal_size((132, 40)))
    assert terminal_text.console_width() == 72                # COLUMNS first, as rich and the shells do
    monkeypatch.delenv("COLUMNS")
    assert terminal_text.console_width() == 132
    terminal_text.set_width(90)
    try:
        assert terminal_text.console_width() == 90 and terminal_text.stdout_console().width == 90
    finally:
        terminal_text.set_width(None)


@pytest.mark.unit
def test_width_option_is_checked(capsys):
    assert main(["verify", "nowhere", "--width", "12"]) == 2
    assert "40 to 1000 columns" in capsys.readouterr().err


@pytest.mark.unit
def test_a_table_keeps_its_words_and_notes_wrap_with_a_hanging_indent():
    from rich.table import Table

    console = terminal_text.SafeConsole(width=50, record=True, file=io.StringIO())
    t = Table(title="t")
    for col in ("stage", "corrected", "RMS corrected / floor"):
        t.add_column(col)
    t.add_row("after correction (all passes pooled)", "81", "0.96")
    t.add_row("uncorrected (planned joints)", "0", "-")
    console.print(terminal_text.keep_words(t, console.width))
    terminal_text.print_notes(console, ["registration_drift: held-out RMS 0.0334 -> 0.0349 mm (gain -4.7 %, t = "
                                        "-1.8): not a significant gain"])
    text = console.export_text()
    _check_lines(text, 50)
    _check_words(text, ["after correction (all passes pooled)", "uncorrected (planned joints)",
                        "RMS corrected / floor", "registration_drift: held-out", "significant"])
    lines = text.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("[1] "))
    assert lines[first + 1].startswith("    ") and lines[first + 1].strip()


@pytest.mark.unit
def test_text_wraps_between_words_and_keeps_a_long_path_whole():
    console = terminal_text.SafeConsole(width=40, record=True, file=io.StringIO())
    path = "/tmp/" + "very-long-directory-name/" * 3 + "report.json"
    console.print(f"wrote {path} and model.json   (three spaces kept)")
    lines = console.export_text().splitlines()
    assert lines == ["wrote", path, "and model.json   (three spaces kept)"]
    errors = terminal_text.stderr_console()
    assert errors.soft_wrap                                  # an error stays one line, whatever its length
