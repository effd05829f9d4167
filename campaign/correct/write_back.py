"""Writing corrected targets: the configured controller's formats (RAPID module, UR JSON + URScript) and the CSV
tables of accepted and rejected targets, each written atomically."""
from __future__ import annotations

import csv
from pathlib import Path

from campaign.config.schema import CampaignConfig
from campaign.errors import one_line
from campaign.io.csv_cells import restore

from .bounds import Rejected
from .target_csv import write_rejected_csv
from .targets import limits_deg


FORMATS = {"rapid": ("CalTargets.mod",), "ur": ("targets_ur.json", "targets_ur.script"), "csv": ("targets.csv",)}


def controller_formats(cfg: CampaignConfig) -> tuple[str, ...]:
    """Write-back formats that fit the configured controller: the robot url's driver, else the robot model's
    vendor (a mock cell of an ABB or UR arm); the CSV always."""
    import re

    scheme = cfg.robot.url.split("://", 1)[0]
    model = cfg.robot.model.lower()
    if scheme == "abb-rws" or (scheme == "mock" and ("abb" in model or re.search(r"\birb", model))):
        return ("rapid", "csv")
    if scheme == "ur-rtde" or (scheme == "mock" and ("universal robots" in model or re.match(r"ur\d", model))):
        return ("ur", "csv")
    return ("csv",)


def _format_rejections(accepted, formats) -> tuple[list, list[Rejected]]:
    """Targets a chosen format cannot hold (RAPID: ids over 80 characters or not ISO 8859-1) -> rejected."""
    if "rapid" not in formats:
        return list(accepted), []
    from drivers.rapid.literals import rapid_string

    ok, bad = [], []
    for t in accepted:
        try:
            rapid_string(t.target_id)
            ok.append(t)
        except ValueError as exc:
            bad.append(Rejected(t.target_id, f"cannot be written to RAPID: {one_line(exc)}"))
    return ok, bad


def write_corrected(cfg: CampaignConfig, accepted, rejected, out_dir: str | Path,
                    formats: tuple[str, ...] | None = None) -> list[Path]:
    """The write-back files of ``formats`` (default: those of the configured controller, see
    ``controller_formats``) and ``rejected.csv``. Every file is rendered in memory first, so a target no format
    can hold writes nothing; ``CampaignError`` when no target is left to write (rejected.csv is still written)."""
    from campaign.errors import CampaignError
    from campaign.io.durable import atomic_write
    from .rapid_module import render_rapid_module
    from .target_csv import render_targets_csv
    from .ur_program import render_ur_json, render_urscript

    formats = controller_formats(cfg) if not formats else tuple(formats)
    accepted, unfit = _format_rejections(accepted, formats)
    rejected = list(rejected) + unfit
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lo, hi = limits_deg(cfg)
    limits = dict(q_min_deg=lo, q_max_deg=hi)
    rejected_path = write_rejected_csv(out / "rejected.csv", rejected)
    if not accepted:
        first = f"; first reason: {rejected[0].target_id}: {rejected[0].reason}" if rejected else ""
        raise CampaignError(f"{out}: nothing to write: all {len(rejected)} targets rejected (reasons in "
                            f"{rejected_path}){first}")
    renderers = {"CalTargets.mod": render_rapid_module, "targets_ur.json": render_ur_json,
                 "targets_ur.script": render_urscript, "targets.csv": render_targets_csv}
    texts = {}
    for fmt in formats:
        for name in FORMATS[fmt]:
            try:
                extra = {"axes": _abb_axes(cfg)} if fmt == "rapid" else {}
                texts[name] = renderers[name](accepted, **limits, **extra)
            except ValueError as exc:
                raise CampaignError(f"{out / name}: not written: {one_line(exc)}") from None
    paths = [atomic_write(out / name, text.encode("utf-8")) for name, text in texts.items()]
    return paths + [rejected_path]


def _abb_axes(cfg: CampaignConfig):
    """How the config's joints map onto an ABB controller's axes (ValueError: no ABB layout, one line)."""
    from drivers.abb_axes import axes_layout

    return axes_layout(cfg.robot.n_joints, cfg.robot.track is not None)


def read_rejected(out_dir: str | Path) -> list[tuple[str, str]]:
    """(target_id, reason) rows of OUT_DIR/rejected.csv (empty when the file is absent)."""
    try:
        with open(Path(out_dir) / "rejected.csv", newline="", encoding="utf-8") as fh:
            return [(restore(row[0]), restore(row[1]) if len(row) > 1 else "") for row in list(csv.reader(fh))[1:]
                    if row]
    except OSError:
        return []
