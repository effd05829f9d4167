"""``campaign report``: one self-contained HTML file (no network, images embedded) from a run's JSON documents.

Sources, all optional but at least one, found in the run (or output) directory:

* ``report.json`` -- the calibration report (``campaign-report/1``) or the ISO 9283 report (``campaign-iso9283/1``);
* ``diagnosis.json`` -- written by ``campaign diagnose`` (``campaign-diagnosis/1``);
* ``verify-*/verify.json`` -- closed-loop verification passes (``campaign-verify/1``);
* ``iso9283-*/report.json`` -- beside a calibration report: the ISO 9283 runs made with its model, listed and
  linked (``campaign.workflows.run_iso9283`` puts them there).

Nothing is computed here: every number printed comes from these documents through :func:`_num`, which also
tags it with ``data-doc``/``data-key``/``data-value`` so a browser test can compare the page with the JSON.
Figures are drawn from the same documents (``html_figures``) and also written as PNG files in a directory named
after the HTML file (``report.html`` -> ``report_figures/``), indexed by what they were drawn from
(``figure_index``): a report written again draws only what changed. Output paths are owned
(:mod:`campaign.run.output_dirs`).
"""
from __future__ import annotations

import base64
import html
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from jinja2 import Environment, PackageLoader, StrictUndefined, select_autoescape
from markupsafe import Markup

from campaign.errors import DataError
from drivers.redaction import redact, redact_url

from campaign.io.durable import atomic_write
from campaign.run.output_dirs import Claim, check_campaign_dir, check_dir, check_file, live_check
from campaign.calibrate.calibration_report import COMPENSATED, ELASTIC, IDENTIFICATION_KEYS, KINEMATIC, STAGES, CalibrationReport
from campaign.io.json_fields import RecordError
from campaign.correct.verify_report import VerifyReport
from campaign.calibrate.report_points import PointTable

from .glossary import GLOSSARY, UNCORRECTED_VS_NOMINAL
from campaign.io.quantities import FLOOR_FMT, condition_meaning, condition_scale
from .diagnosis_text import effect_label
from .summary_text import (FORMATS, banner, diagnosis_line, held_out_line, iso_ap_line, iso_rp_line, iso_targets_line,
                           iso_verdict_line, model_line, origin, outliers_line, reason_lines, simulated_banner, verdict_line,
                           verified_line)

CALIBRATION, ISO, DIAGNOSIS, VERIFY = "campaign-report/1", "campaign-iso9283/1", "campaign-diagnosis/1", "campaign-verify/1"


@dataclass(frozen=True)
class ReportSources:
    """What one report is made of: the calibration and verification reports as records, the ISO 9283 and
    diagnosis documents (JSON), the calibration's per-point rows, and the parsed JSON documents by name
    (``calibration``, ``verify0``...: what :func:`_num` reads and tags); a record without its document is tagged
    from its ``to_dict()``."""
    title: str
    calibration: CalibrationReport | None = None
    iso9283: dict | None = None
    diagnosis: dict | None = None
    verify: tuple[VerifyReport, ...] = ()
    files: dict = field(default_factory=dict)          # doc name -> relative path, for the page's source list
    documents: dict = field(default_factory=dict)      # doc name -> parsed JSON document
    points: PointTable | None = None                   # the calibration's per-point rows (inline or points.csv)
    iso_runs: tuple[tuple[str, dict], ...] = ()        # (directory, ISO report) of the runs made with this model

    def docs(self) -> dict:
        """Every document by name (the parsed one, else the record's ``to_dict()``)."""
        out = {k: v for k, v in (("calibration", self.calibration), ("iso9283", self.iso9283),
                                 ("diagnosis", self.diagnosis)) if v is not None}
        out.update({f"verify{i}": v for i, v in enumerate(self.verify)})
        out.update({f"isorun{i}": doc for i, (_, doc) in enumerate(self.iso_runs)})
        return {k: self.documents.get(k) or (v.to_dict() if hasattr(v, "to_dict") else v) for k, v in out.items()}


def _read(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise DataError(str(path), f"not a readable JSON report: {exc}") from None


def _checked(doc: dict, path: Path, record):
    """``record.from_dict(doc)`` (a DataError names the file and the field otherwise)."""
    try:
        return record.from_dict(doc)
    except RecordError as exc:
        raise DataError(str(path), exc.message) from None


def collect(directory: str | os.PathLike) -> ReportSources:
    """Find the JSON documents of a run or output directory; DataError when there are none."""
    d = Path(directory)
    if not d.is_dir():
        raise DataError(str(d), "not a directory (campaign report takes a run or output directory)")
    found: dict = {}
    files, docs, points = {}, {}, None
    if (d / "report.json").exists():
        doc = _read(d / "report.json")
        kind = {CALIBRATION: "calibration", ISO: "iso9283"}.get(doc.get("format"))
        if kind is None:
            raise DataError(str(d / "report.json"), f"unknown report format {doc.get('format')!r}")
        found[kind] = _checked(doc, d / "report.json", CalibrationReport) if kind == "calibration" else doc
        files[kind], docs[kind] = "report.json", doc
        if kind == "calibration" and found[kind].points:
            points = PointTable.of(found[kind].points, d)                # inline, or points.csv of a large run
    if (d / "diagnosis.json").exists():
        found["diagnosis"], files["diagnosis"] = _read(d / "diagnosis.json"), "diagnosis.json"
    verify = []
    for i, p in enumerate(sorted(d.glob("verify-*/verify.json"))):
        docs[f"verify{i}"] = doc = _read(p)
        verify.append(_checked(doc, p, VerifyReport))
        files[f"verify{i}"] = str(p.relative_to(d))
    if not found and not verify:
        raise DataError(str(d), "no report.json, diagnosis.json or verify-*/verify.json to report on")
    iso_runs = _iso_runs(d, files, docs) if "calibration" in found else ()
    first = next((docs.get(k, found[k]) for k in ("calibration", "iso9283", "diagnosis") if k in found), {})
    return ReportSources(f"{first.get('config', d.name)}: {d.name}", verify=tuple(verify), files=files,
                         documents=docs, points=points, iso_runs=iso_runs, **found)


def _iso_runs(d: Path, files: dict, docs: dict) -> tuple[tuple[str, dict], ...]:
    """The ISO 9283 reports in ``D/iso9283-*/`` (runs made with D's model), added to ``files``/``docs``."""
    from .iso9283 import RUN_PREFIX

    out = []
    for p in sorted(d.glob(f"{RUN_PREFIX}*/report.json")):
        doc = _read(p)
        if doc.get("format") == ISO:
            files[f"isorun{len(out)}"], docs[f"isorun{len(out)}"] = str(p.relative_to(d)), doc
            out.append((p.parent.name, doc))
    return tuple(out)


def _lookup(doc: dict, key: str):
    node = doc
    for part in key.split("."):
        node = node[int(part)] if isinstance(node, list) else node[part]
    return node


def _num_factory(docs: dict):
    """``num(doc, key, fmt)``: the value at dotted ``key`` of document ``doc``, formatted, in a tagged span."""
    def num(doc: str, key: str, fmt: str = ".3f", scale: float = 1.0) -> Markup:
        value = _lookup(docs[doc], key)
        if value is None:
            return Markup(f'<span class="num" data-doc="{doc}" data-key="{html.escape(key)}" data-value="null">-</span>')
        text = format(value * scale, fmt) if scale != 1.0 else format(value, fmt)
        return Markup(f'<span class="num" data-doc="{doc}" data-key="{html.escape(key)}" data-scale="{scale!r}" '
                      f'data-fmt="{html.escape(fmt)}" data-value="{value!r}">{html.escape(text)}</span>')
    return num


def figure_sections(src: ReportSources, reuse_from=()) -> dict:
    """{section: figure_index.Section} of the report, in page order: each section's figures taken from the first
    figures directory of ``reuse_from`` that indexes them under the same key (:mod:`.figure_index`), else drawn
    from the documents."""
    from . import html_figures as hf
    from .figure_index import Section, reused, section_key

    docs, out = src.docs(), {}

    def section(name: str, draw, *inputs) -> None:
        key = section_key(name, *inputs)
        figs = reused(reuse_from, name, key)
        out[name] = Section(key, figs if figs is not None else tuple(f for f in draw() if f is not None))

    if src.calibration:
        p = src.points
        rows = None if p is None else (p.point_id, p.set, p.q_deg, p.p_base_mm, p.err_base_mm, p.used, p.t_s,
                                        p.pred_std_mm)
        doc = {k: v for k, v in docs["calibration"].items() if k != "points"}   # the rows, hashed as arrays
        section("calibration", lambda: hf.calibration_figures(src.calibration, p), doc, rows)
        if src.calibration.budget is not None:
            budget = src.calibration.budget.to_dict()
            section("budget", lambda: [hf.budget_figure(budget)], budget)
    for i, v in enumerate(src.verify):
        if v.stages:
            section(f"verify{i}", lambda v=v, i=i: [hf.verify_figure(v, i)], docs[f"verify{i}"], i)
    if src.diagnosis and src.diagnosis.get("maps"):
        section("diagnosis", lambda: diagnosis_figures(src.diagnosis), src.diagnosis)
    if src.iso9283:
        section("iso9283", lambda: hf.iso_figures(src.iso9283), src.iso9283)
    return out


def _by_part(sections: dict) -> dict[str, list]:
    """Figures per part of the page (lists of html_figures.Figure): ``calibration``, ``budget``, ``verify`` (every
    verification's), ``diagnosis``, ``iso9283``."""
    figs: dict[str, list] = {"calibration": [], "verify": [], "diagnosis": [], "iso9283": [], "budget": []}
    for name, s in sections.items():
        figs["verify" if name.startswith("verify") else name] += s.figures
    return figs


def build_figures(src: ReportSources, reuse_from=()) -> dict[str, list]:
    """The report's figures per part of the page (:func:`_by_part`; :func:`figure_sections`)."""
    return _by_part(figure_sections(src, reuse_from))


def diagnosis_figures(report: dict) -> list:
    """The diagnose command's maps (workspace, joints, time, shrinkage) as report figures."""
    import tempfile

    from .budget_plot import BUDGET_CAPTION, BUDGET_TITLE
    from .diagnosis_plots import write_plots
    from .html_figures import Figure

    titles = {"where_workspace": "Where the residual lies: workspace cells",
              "where_joints": "Where the residual lies: each joint's range",
              "where_time": "Where the residual lies: over time",
              "shrinkage": "How far the error shrinks with each accepted effect",
              "budget_waterfall": BUDGET_TITLE}
    with tempfile.TemporaryDirectory() as tmp:
        paths = write_plots(report, tmp)
        if isinstance(paths, str):
            return []
        # the calibration's own budget figure is budget_waterfall.png in the same figures directory
        return [Figure("diagnosis_budget_waterfall" if p.stem == "budget_waterfall" else p.stem,
                       titles.get(p.stem, p.stem), BUDGET_CAPTION if p.stem == "budget_waterfall" else
                       "From the diagnosis.", p.read_bytes()) for p in paths]


HTML_FORMATS = {**FORMATS, "mm": ".4f"}
"""The summary's formats in HTML: mm figures as in the page's Table 3."""


def summary_markup(src: ReportSources, num) -> dict | None:
    """The summary's lines (``campaign.report.summary_text``) as HTML, every number tagged with its
    ``summary.*`` key of report.json, then a line per verification (its ``verify.json``) and the diagnosis's
    headline (``diagnosis.json``) when those have run; None without a summary."""
    s = None if src.calibration is None else src.calibration.summary
    if s is None:
        return None
    def n(key: str, kind: str) -> Markup:
        return num("calibration", f"summary.{key}", HTML_FORMATS[kind])

    def of(doc: str):
        return lambda key, kind, scale=1.0: num(doc, key, HTML_FORMATS[kind], scale)
    t = Markup.escape
    verified = [verified_line(v, of(f"verify{i}"), t) for i, v in enumerate(src.verify)]
    diagnosis = diagnosis_line(src.diagnosis, of("diagnosis"), effect_label, t) if src.diagnosis else None
    return {"banner": banner(s), "origin": origin(s), "model": model_line(s, n, t), "reasons": reason_lines(s, t),
            "held_out": held_out_line(s, n, t), "outliers": outliers_line(s, n, t),
            "verdict": verdict_line(s, n, t), "result": s.verdict.result,
            "verified": verified, "diagnosis": diagnosis}


def cv_predicted_keys(report: CalibrationReport | None) -> dict[str, str]:
    """Per stage, the report.json key of its CV-predicted held-out RMS (k-fold CV on the calibration points): the
    effect selection's figures for the kinematic stage (geometry alone) and the physical-effects stage, the
    residual layer's own CV for a final model with a layer (else the final model is the physical-effects one).
    Stages without such a record are absent (the nominal stage is never cross-validated)."""
    if report is None:
        return {}
    sel = report.effects.selection if report.effects else None
    keys = {}
    if sel and sel.get("geometric_cv_rms_mm") is not None:
        keys[KINEMATIC] = "effects.selection.geometric_cv_rms_mm"
    if sel and sel.get("final_cv_rms_mm") is not None:
        keys[ELASTIC] = keys[COMPENSATED] = "effects.selection.final_cv_rms_mm"
    layer = report.final.layer if report.final else None
    if layer is not None:
        keys[COMPENSATED] = "stages.compensated.layer.cv_predicted_rms_mm"
    return {k: v for k, v in keys.items() if k in report.stages}


def iso_summary_markup(doc: dict | None, num) -> dict | None:
    """The ISO 9283 report's summary lines (``campaign.report.summary_text``) as HTML, every number tagged with its
    key; None for a report of an earlier version (no ``summary``)."""
    if doc is None or "summary" not in doc:
        return None
    def n(key: str, kind: str) -> Markup:
        return num("iso9283", key, HTML_FORMATS[kind])
    t = Markup.escape
    return {"banner": simulated_banner(doc["summary"]["simulated_devices"]), "targets": iso_targets_line(doc, t),
            "ap": iso_ap_line(doc, n, t), "rp": [iso_rp_line(doc, i, n, t) for i in range(len(doc["runs"]))],
            "verdict": iso_verdict_line(doc, n, t), "result": doc["summary"]["verdict"]["result"]}


def render_html(src: ReportSources, figures: dict[str, list], figures_name: str = "report_figures") -> str:
    env = Environment(loader=PackageLoader("campaign.report", "templates"), autoescape=select_autoescape(["html", "j2"]),
                      undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    env.filters["url"] = lambda value: redact_url(str(value))    # a device URL: its user-info masked whole
    b64 = {f.name: base64.b64encode(f.png).decode() for fs in figures.values() for f in fs}
    num = _num_factory(src.docs())
    ident = dict(src.calibration.identification) if src.calibration else {
        k: src.iso9283[k] for k in IDENTIFICATION_KEYS if k in (src.iso9283 or {})}
    return env.get_template("report.html.j2").render(
        src=src, figures=figures, b64=b64, num=num, stages=STAGES, floor_fmt=FLOOR_FMT, ident=ident,
        summary=summary_markup(src, num), figures_name=figures_name, glossary=GLOSSARY,
        iso_summary=iso_summary_markup(src.iso9283, num),
        cv_keys=cv_predicted_keys(src.calibration), effect_label=effect_label,
        uncorrected_vs_nominal=UNCORRECTED_VS_NOMINAL,
        condition=condition_scale, condition_meaning=condition_meaning, n_figures=sum(len(v) for v in figures.values()))


def figures_dir(html: Path) -> Path:
    """Where a report's figures go as PNG: a directory named after it (``report.html`` -> ``report_figures/``)."""
    return html.with_name(f"{html.stem}_figures")


def report_targets(directory: str | os.PathLike, out: str | os.PathLike | None = None,
                   overwrite: bool = False) -> tuple[Path, Claim]:
    """The HTML file and the figures directory a report of DIRECTORY writes, checked before anything is computed:
    DIRECTORY/report.html when DIRECTORY is a campaign directory (a run's or a command's output), else ``out``,
    which must not exist unless ``overwrite``; the figures directory must be new, empty or this report's.
    DataError (nothing written) otherwise (:mod:`campaign.run.output_dirs`)."""
    directory = Path(directory)
    default = directory / "report.html"
    if out is None or Path(out).resolve() == default.resolve():
        if not overwrite:
            check_campaign_dir(directory, "report")
        elif directory.is_dir():
            live_check(directory, "report")                  # --overwrite never writes into a live run either
        html = check_file(default, overwrite=True, own=True)  # the directory's own report, written again
    else:
        html = check_file(out, overwrite)
    return html, check_dir(figures_dir(html), "figures", overwrite, source=html.name, option="figures directory")


def write_report(directory: str | os.PathLike, out: str | os.PathLike | None = None, overwrite: bool = False,
                 sources: ReportSources | None = None) -> Path:
    """Write DIRECTORY/report.html (or ``out``) from the documents in DIRECTORY (or ``sources``), and its figures as
    PNG in the directory named after it (:func:`figures_dir`) with their index; every file atomically, after
    :func:`report_targets` accepted the paths. Figures whose documents are unchanged are taken from the figures
    directory written to or from DIRECTORY's own report (:mod:`.figure_index`), not drawn again."""
    from .figure_index import INDEX, index_document, same_file

    html, figures_claim = report_targets(directory, out, overwrite)
    src = sources if sources is not None else collect(directory)
    sections = figure_sections(src, (figures_claim.path, figures_dir(Path(directory) / "report.html")))
    png_dir = figures_claim.take()
    for s in sections.values():
        for f in s.figures:
            if not same_file(png_dir / f"{f.name}.png", f.png):
                atomic_write(png_dir / f"{f.name}.png", f.png)
    atomic_write(png_dir / INDEX, index_document(sections))
    atomic_write(html, redact(render_html(src, _by_part(sections), png_dir.name)).encode())
    return html
