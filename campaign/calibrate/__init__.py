"""From a dataset to a calibrated model and its report: preparation (joint set, tracker drift from the nests),
plausibility checks, the calibration stages (geometry with the fault screen, physical effects, residual layer),
multi-SMR, ``report.json`` as a typed record and its per-point table, model/report files (``outputs``), and the
sim-to-real gap diagnosis (``diagnosis``). Imports data, run (records), plan, config and robocal."""
from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "adaptive_rounds": ("AdaptiveRounds",),
    "adaptive_stop": ("AdaptivePasses", "stop_summary"),
    "calibration_report": ("COMPENSATED", "CalibrationReport", "ELASTIC", "IDENTIFICATION_KEYS", "KINEMATIC",
                           "NOMINAL", "STAGES"),
    "diagnosis": ("diagnose_source", "write_diagnosis_json"),
    "learning": ("forecast_event", "learning_summary", "plan_learning"),
    "multi_smr": ("angle_stats", "measured_flange_poses", "pose_estimator", "tool_orientation_errors_arcsec"),
    "outputs": ("load_model", "output_files", "run_files", "write_outputs"),
    "plausibility": ("Plausibility", "check_deltas", "plausibility_lines"),
    "prepare": ("fit_nest_drift",),
    "report_points": ("PointTable",),
    "report_sections": ("ErrorFigures", "LayerSummary", "VerifyPass"),
    "select_adaptive": ("adaptive_selection",),
    "selection": ("select_rows",),
    "stages": ("Calibrated", "REPORT_FORMAT", "calibrate_dataset"),
    "summary": ("FAIL", "PASS", "Summary", "summarize", "taken_of_tried"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
