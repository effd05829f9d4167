"""Using a calibrated model: target correction (``targets``) and the error it predicts (``accuracy``), the safety
bounds of corrected targets (``bounds``), the write-back formats (``rapid_module``, ``ur_program``, ``target_csv``,
``write_back``), closed-loop verification and ``verify.json`` (``verify``, ``verify_report``). Imports calibrate
(model files), run, plan, config, robocal and ``drivers.rapid``."""
