"""Using a calibrated model: target correction (``targets``) and the error it predicts (``accuracy``), the safety
bounds of corrected targets (``bounds``), the write-back formats (``rapid_module``, ``ur_program``, ``target_csv``,
``write_back``), closed-loop verification and ``verify.json`` (``verify``, ``verify_report``). Imports calibrate
(model files), run, plan, config, robocal and ``drivers.rapid``."""
from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "accuracy": ("held_out_of", "summary_lines"),
    "targets": ("Targets", "check_model_fits", "correct_targets", "read_targets_csv", "recorded_identity"),
    "verify": ("verify_run",),
    "verify_drift": ("VerifyDrift",),
    "verify_report": ("POOLED", "UNCORRECTED", "VerifyReport"),
    "write_back": ("read_rejected", "write_corrected"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
