"""From a dataset to a calibrated model and its report: preparation (joint set, tracker drift from the nests),
plausibility checks, the calibration stages (geometry with the fault screen, physical effects, residual layer),
multi-SMR, ``report.json`` as a typed record and its per-point table, model/report files (``outputs``), and the
sim-to-real gap diagnosis (``diagnosis``). Imports data, run (records), plan, config and robocal."""
