"""The HTML report: written by run / reprocess / diagnose from the JSON documents, self-contained, and checked
in a real headless Chromium (no console errors, every image decodes, DOM numbers equal the JSON)."""
import json
from pathlib import Path

import pytest
import yaml

from campaign.cli import main
from tests.campaign.browser import Chromium, skip_without_browser
from tests.campaign.helpers import ROOT, read_report, small_config
from tests.campaign.report.html_page import empty_columns, read_page, sentence_joins

needs_browser = pytest.mark.skipif(skip_without_browser(), reason="chromium not installed (tests/run installs it)")


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
    isos = sorted(run_dir.glob("iso9283-*/report.json"))              # ISO runs listed by a calibration report
    for n in page.numbers:
        doc_name = n["doc"]
        path = verify[int(doc_name[6:])] if doc_name.startswith("verify") else isos[int(doc_name[6:])] \
            if doc_name.startswith("isorun") else run_dir / docs[doc_name]
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
    """A small geometric-only mock run with the demo's reference nests, an acceptance criterion, then ``verify``
    and ``diagnose`` (each rewrites report.html)."""
    tmp = tmp_path_factory.mktemp("report")
    nests = yaml.safe_load((ROOT / "configs" / "irb2600.yaml").read_text())["plan"]["nests"]
    cfg = small_config(tmp, acceptance={"max_rms_mm": 0.1, "max_mm": 0.3}, **{"plan.nests": nests})
    assert main(["run", str(cfg), "--out", str(tmp / "run")]) == 0
    assert main(["verify", str(tmp / "run")]) == 0                 # rewrites report.html with the verify passes
    assert main(["diagnose", str(tmp / "run"), "--config", str(cfg)]) == 0      # and with the diagnosis
    return tmp / "run", cfg


@pytest.mark.system
def test_run_writes_report_html_and_png_figures(mock_run):
    run_dir, _ = mock_run
    html = (run_dir / "report.html").read_text()
    pngs = sorted(p.name for p in (run_dir / "report_figures").glob("*.png"))
    assert len(pngs) >= 6 and html.count("<figure") == len(pngs)
    report = read_report(run_dir)
    assert len(report.points["point_id"]) == report.n.calib + report.n.test + report.n.check
    assert "Position error on the held-out test set" in html and "Identifiability" in html and "Excluded points" in html
    final_rms = report.stages["compensated"].test.rms_mm                   # the RMS / floor column, as the terminal's
    assert (f'data-key="stages.compensated.test.rms_mm" data-scale="{1.0 / report.noise_floor_mm!r}" data-fmt=".2f" '
            f'data-value="{final_rms!r}">{final_rms / report.noise_floor_mm:.2f}</span>') in html


@pytest.mark.system
@needs_browser
def test_mock_run_report_in_headless_chromium(mock_run, tmp_path):
    run_dir, _ = mock_run
    page = check_page(run_dir, tmp_path, "mock-run")
    keys = {n["key"] for n in page.numbers}
    assert {f"stages.{s}.test.rms_mm" for s in ("nominal", "kinematic", "compensated")} <= keys
    assert {"noise_floor_mm", "condition_number", "residual_choice.candidates.none.cv_rms_mm"} <= keys
    assert any(n["doc"] == "verify0" and n["key"].endswith(".rms_mm") for n in page.numbers)
    assert page.figures >= 6 and "Position error on the held-out test set" in page.text and "Closed-loop verification" in page.text


def _strings(node) -> list[str]:
    """Every string value of a JSON document, longest first."""
    if isinstance(node, str):
        return [node]
    items = node.values() if isinstance(node, dict) else node if isinstance(node, list) else ()
    return sorted((t for v in items for t in _strings(v)), key=len, reverse=True)


@pytest.mark.system
@needs_browser
def test_summary_first_and_traceability_in_headless_chromium(mock_run, tmp_path):
    """The summary is the first section: SIMULATED banner, the model in one line, the held-out figures and the
    verdict, every number in it tagged with its report.json key and equal to it (the untagged text holds no digit
    that is not one of the strings of the documents it reads); the traceability section shows the serials and
    points to the sign-off at the end."""
    run_dir, _ = mock_run
    doc = json.loads((run_dir / "report.json").read_text())
    summary = doc["summary"]
    with Chromium(tmp_path / "profile") as browser:
        page = browser.load((run_dir / "report.html").resolve().as_uri())
        sections = browser.evaluate("[...document.querySelectorAll('section')].map(s => s.id)")
        got = browser.evaluate("""(() => { const s = document.querySelector('section#summary');
            const bare = s.cloneNode(true); bare.querySelectorAll('[data-key]').forEach(e => e.remove());
            return {text: s.innerText, bare: bare.textContent, model: document.querySelectorAll('#summary-model').length,
                    banner: (document.querySelector('#simulated-banner') || {}).innerText || '',
                    keys: [...s.querySelectorAll('[data-key]')].filter(e => e.dataset.doc == 'calibration')
                                .map(e => e.dataset.key),
                    trace: document.querySelector('section#traceability').innerText}; })()""")
    assert page.errors == [] and check_numbers(page, run_dir) > 0
    assert sections[0] == "summary" and "traceability" in sections and sections[-1] == "signoff"
    assert got["banner"].startswith("SIMULATED") and summary["simulated_devices"] == ["robot", "tracker"]
    assert got["model"] == 1 and "parameters identified" in got["text"] and "residual layer" in got["text"]
    assert "verdict: PASS" in got["text"] and summary["verdict"]["result"] == "pass"
    assert {"summary.held_out.mean_mm", "summary.held_out.rms_mm", "summary.held_out.max_mm",
            "summary.rms_over_floor", "summary.noise_floor_mm", "summary.verdict.max_rms_mm",
            "summary.verdict.max_mm", "summary.model.n_identified"} <= set(got["keys"])
    assert all(k.startswith("summary.") for k in got["keys"])
    bare = got["bare"]
    diagnosis = json.loads((run_dir / "diagnosis.json").read_text())
    for text in sorted(_strings(summary) + _strings(diagnosis), key=len, reverse=True):
        bare = bare.replace(text, "")
    assert not any(c.isdigit() for c in bare), bare                     # no number that is not from report.json
    final = doc["stages"]["compensated"]["test"]
    assert summary["held_out"] == final and summary["noise_floor_mm"] == doc["noise_floor_mm"]
    assert summary["rms_over_floor"] == pytest.approx(final["rms_mm"] / doc["noise_floor_mm"], rel=1e-12)
    for role in ("robot", "tracker"):
        assert doc[f"{role}_identity"]["serial"] in got["trace"]
    assert doc["config_sha256"] in got["trace"] and "end of this report" in got["trace"]


def _tagged(html_fragment: str) -> set[tuple[str, str]]:
    """(data-doc, data-key) of every tagged number in a piece of the page."""
    import re
    return set(re.findall(r'data-doc="([^"]+)" data-key="([^"]+)"', html_fragment))


def _element(html: str, element_id: str) -> str:
    """The HTML of the element with this id, up to its closing tag (no nesting of the same tag inside)."""
    start = html.index(f'id="{element_id}"')
    tag = html[html.rindex("<", 0, start) + 1:start].split()[0]
    return html[start:html.index(f"</{tag}>", start)]


@pytest.mark.system
def test_signoff_comes_last_and_the_summary_states_verify_and_diagnosis(mock_run):
    """The sign-off is the page's last section, after everything it signs (verification, diagnosis); the summary
    gives the verified accuracy from verify.json (the corrected passes pooled, against verify's noise floor) and the
    diagnosis's headline from diagnosis.json, every number tagged with its key there."""
    from campaign.correct.verify_report import POOLED

    run_dir, _ = mock_run
    html = (run_dir / "report.html").read_text()
    page = read_page(html)
    order = page.sections
    assert order[-1] == "signoff" and order.count("signoff") == 1 and html.count('class="signoff"') == 1
    assert all(order.index(s) < order.index("signoff") for s in ("summary", "traceability", "verify", "diagnosis"))
    verified = _element(html, "summary-verified-0")
    pooled = f"stages.{POOLED}"
    assert {("verify0", f"{pooled}.rms_mm"), ("verify0", f"{pooled}.max_mm"), ("verify0", "noise_floor_mm"),
            ("verify0", "n")} <= _tagged(verified)
    v = json.loads(next(run_dir.glob("verify-*/verify.json")).read_text())
    assert f'data-value="{v["stages"][POOLED]["rms_mm"]!r}">{v["stages"][POOLED]["rms_mm"]:.4f}<' in verified
    diag = json.loads((run_dir / "diagnosis.json").read_text())
    headline = _element(html, "summary-diagnosis")
    assert {("diagnosis", "baseline_test_rms_mm"), ("diagnosis", "final_test_rms_mm")} <= _tagged(headline)
    accepted = [f["evidence"]["label"] for f in diag["findings"] if f["accepted"]]
    assert all(label in headline for label in accepted) and ("none" in headline) == (not accepted)
    assert ("nothing unexplained" in headline) == (not diag["unexplained"])
    assert html.index('id="summary-verified-0"') < html.index('id="summary-verdict"') < html.index('id="cell"')


@pytest.mark.system
def test_tracker_drift_section_from_the_preparation_record(mock_run):
    """The nests' drift (report.json preparation.drift, as the terminal prints it) has its own section: nests,
    readings, largest move, compensated or not and why, translation at the end, the CV of each drift model."""
    run_dir, _ = mock_run
    html = (run_dir / "report.html").read_text()
    drift = json.loads((run_dir / "report.json").read_text())["preparation"]["drift"]
    assert drift["nests"] == 3 and drift["readings"] > 0
    section = _element(html, "drift")
    keys = {k for d, k in _tagged(section) if d == "calibration"}
    assert {"preparation.drift.nests", "preparation.drift.readings", "preparation.drift.max_nest_move_mm",
            "preparation.drift.translation_at_end_mm.2"} <= keys
    assert {f"preparation.drift.model.cv_rms_mm.{k}" for k in drift["model"]["cv_rms_mm"]} <= keys
    text = read_page(html).text
    assert f"Tracker drift from {drift['nests']} reference nests ({drift['readings']} readings" in text
    assert ("compensated" if drift["applied"] else "not compensated") in text and drift["why"] in text


@pytest.mark.system
def test_no_empty_column_and_no_layer_note_without_a_layer(mock_run):
    """No table column is "-" all the way down (the CV-predicted column is filled from the effect selection's CV, or
    absent); without a residual layer the page says none was kept and carries no note about a layer's fit."""
    run_dir, _ = mock_run
    html = (run_dir / "report.html").read_text()
    page = read_page(html)
    assert {name: empty_columns(rows) for name, rows in page.tables.items() if empty_columns(rows)} == {}
    report = read_report(run_dir)
    assert report.final.layer is None and report.method.residual == "none"
    table3 = page.tables["table3-table"]
    assert "CV-predicted held-out RMS (mm) k-fold CV on the calibration points" in table3[0]
    sel = report.effects.selection
    cv = {row[0]: row[-1] for row in table3[1:]}
    assert cv["kinematic calibration"] == f"{sel['geometric_cv_rms_mm']:.4f}" and cv["nominal (uncompensated)"] == "-"
    assert cv["final model (+ residual layer, if any)"] == f"{sel['final_cv_rms_mm']:.4f}"   # no layer: no other CV
    assert cv.get("kinematic + physical effects", f"{sel['final_cv_rms_mm']:.4f}") == f"{sel['final_cv_rms_mm']:.4f}"
    assert 'id="layer-honesty"' not in html and "interpolates" not in page.text
    assert "No residual layer" in _element(html, "residual-none")


@pytest.mark.system
def test_effect_rows_show_what_tells_them_apart(mock_run):
    """Every findings row and every "cannot tell" row names its effect as EffectChoice.label does (with the joints,
    harmonics, clock, degree or time constant that tell candidates apart): no two rows alike, in the HTML and the
    terminal."""
    from rich.console import Console

    from campaign.report.diagnosis_text import effect_label, render

    run_dir, _ = mock_run
    page = read_page((run_dir / "report.html").read_text())
    diag = json.loads((run_dir / "diagnosis.json").read_text())
    rows = page.tables["findings-table"][1:]
    assert [r[0] for r in rows] == [effect_label(f) for f in diag["findings"]]
    assert all(r[0] == f["evidence"]["label"] for r, f in zip(rows, diag["findings"]) if "label" in f["evidence"])
    named = [tuple(r[:2]) for r in rows]
    assert len(set(named)) == len(named) and len({f["effect"] for f in diag["findings"]}) < len(named)
    cannot = [r[0] for t in page.tables.values() if t and t[0][:2] == ["effect", "why not"] for r in t[1:]]
    assert cannot == [effect_label(u) for u in diag["undiagnosable"]] and len(set(cannot)) == len(cannot)
    console = Console(record=True, width=250)
    render(console, diag)
    out = console.export_text()
    assert all(effect_label(f) in out for f in diag["findings"])


@pytest.mark.system
def test_no_sentence_runs_into_the_next(mock_run):
    """The page's text (calibration, verification, diagnosis) has no "mm.The": a period after a word followed by a
    capital letter without a space (code names left out)."""
    run_dir, _ = mock_run
    assert sentence_joins(read_page((run_dir / "report.html").read_text()).text) == []


@pytest.mark.system
def test_report_of_an_earlier_version_says_it_has_no_summary(mock_run, tmp_path):
    run_dir, _ = mock_run
    old = tmp_path / "old"
    old.mkdir()
    doc = json.loads((run_dir / "report.json").read_text())
    del doc["summary"]
    (old / "report.json").write_text(json.dumps(doc))
    assert main(["report", str(old), "--out", str(tmp_path / "old.html")]) == 0
    html = (tmp_path / "old.html").read_text()
    assert 'id="summary-none"' in html and "earlier version" in html and html.index('id="summary"') < html.index(
        'id="cell"')


@pytest.mark.system
def test_report_html_is_byte_reproducible(mock_run, tmp_path):
    """Written twice from the same JSON documents, the report is the same bytes (no clock, no random order).
    The run's report.json and verify pass (the diagnosis left out: its maps would double the drawing time)."""
    import shutil

    run_dir, _ = mock_run
    docs = tmp_path / "docs"
    docs.mkdir()
    shutil.copy(run_dir / "report.json", docs)
    for v in run_dir.glob("verify-*"):
        shutil.copytree(v, docs / v.name)
    assert main(["report", str(docs), "--out", str(tmp_path / "a.html")]) == 0
    assert main(["report", str(docs), "--out", str(tmp_path / "b.html")]) == 0
    a, b = (tmp_path / "a.html").read_text(), (tmp_path / "b.html").read_text()
    assert a.replace("a_figures", "b_figures") == b


@pytest.mark.system
@needs_browser
def test_diagnosis_with_an_effect_in_headless_chromium(tmp_path, capsys):
    cfg = small_config(tmp_path, **{"simulation.effects": [{"name": "backlash", "scale": 1.0}]})
    run_dir = tmp_path / "run"
    assert main(["run", str(cfg), "--out", str(run_dir)]) == 0
    out = " ".join(capsys.readouterr().out.split())      # the summary first, the files last (wrapped or not)
    tail = out[out.index("SIMULATED: the robot and tracker"):]
    assert tail.index("model: ") < tail.index("held-out test set (final model") < tail.index("verdict: none: no "
                                                                                               "acceptance criterion")
    assert tail.index("verdict: none") < tail.index("Position error on the test set")   # then the stage table
    assert tail.endswith(f"run directory {run_dir}: log.jsonl, data.csv (interchange), report.json, model.json, "
                         "effects.yaml, report.html, report_figures/ (PNG)") and (run_dir / "effects.yaml").is_file()
    fitted = read_report(run_dir).effects.fitted[0]["params"]
    assert "effects backlash(J" in tail and f"b1 {fitted['b1']['value']:.3g} rad" in tail
    assert main(["diagnose", str(run_dir), "--config", str(cfg)]) == 0
    diag = json.loads((run_dir / "diagnosis.json").read_text())
    accepted = [f for f in diag["findings"] if f["accepted"]]
    assert accepted and accepted[0]["effect"] == "backlash"
    page = check_page(run_dir, tmp_path, "diagnosis")
    keys = {(n["doc"], n["key"]) for n in page.numbers}
    assert ("diagnosis", "findings.0.test_rms_after_mm") in keys and ("diagnosis", "noise_floor_mm") in keys
    assert page.figures >= 6 + 3 and "Findings" in page.text and "backlash" in page.text
    assert sentence_joins(read_page((run_dir / "report.html").read_text()).text) == []


@pytest.mark.system
def test_report_command_errors_are_one_line(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2                     # the output is checked before any input
    assert "not a directory written by campaign" in capsys.readouterr().err
    (tmp_path / ".campaign-owner.json").write_text(json.dumps({"format": "campaign-owner/1", "kind": "reprocess",
                                                                 "source": "x.csv", "created_utc": "2026-01-01"}))
    assert main(["report", str(tmp_path)]) == 2
    assert "no report.json" in capsys.readouterr().err
    (tmp_path / "report.json").write_text("{not json")
    assert main(["report", str(tmp_path)]) == 2


@pytest.mark.system
def test_the_selections_two_paths_are_stated(mock_run, tmp_path):
    """When the effect selection compared two paths (``robocal.effects.select.LINKS_PATH_GAIN``), the effects
    section states them from report.json; without, no such line."""
    run_dir, _ = mock_run
    doc = json.loads((run_dir / "report.json").read_text())
    assert "path" not in doc["effects"]["selection"]
    for name, path in (("one", None), ("two", "the links' form offered in place of the lever form: final held-out "
                                              "RMS 0.0479 mm, the lever form's path 0.0995 mm; kept the links' path")):
        d = tmp_path / name
        d.mkdir()
        if path:
            doc["effects"]["selection"]["path"] = path
        (d / "report.json").write_text(json.dumps(doc))
        assert main(["report", str(d), "--out", str(tmp_path / f"{name}.html")]) == 0
        text = read_page((tmp_path / f"{name}.html").read_text()).text
        assert (f"Two paths: {path}." in " ".join(text.split())) if path else "Two paths" not in text
