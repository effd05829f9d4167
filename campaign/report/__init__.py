"""Showing results, computing no calibration: terminal tables (``terminal``, ``diagnosis_text``), the self-contained
HTML report and its figures (``html``, ``html_figures``, ``figure_index``, ``templates/``), diagnosis plots, the ISO 9283
characteristics of an acceptance run (``iso9283``) and model export (``export``: URDF, DH tables). Imports
calibrate, correct, data, run, plan, config and robocal."""
from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "adaptive_text": ("render_adaptive_selection", "render_learning", "render_plan_learning"),
    "diagnosis_plots": ("write_plots",),
    "diagnosis_text": ("render", "render_self_check"),
    "export": ("UrdfLimits", "export_model"),
    "html": ("ReportSources", "figures_dir", "report_targets", "write_report"),
    "iso9283": ("RUN_PREFIX", "calibration_dir", "finish", "is_iso_run_of"),
    "summary_text": ("render_summary",),
    "terminal": ("render_forecast", "render_iso", "render_parameters", "render_plan", "render_selection",
                 "render_stages", "render_stop", "render_verify"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
