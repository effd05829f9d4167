"""Measuring on the cell: the devices of a config (``devices``), the runner that moves, measures and logs each point
before the next move (``runner``, ``tracker_quality``, ``traceability``), the durable log and its typed records
(``log_reader``, ``log_writer``, ``log_records``), resume checks, the ETA, one measuring session (``session``: run
directory, log, safety set-up, progress), the output directories every command owns (``output_dirs``: a run
directory is known by its log) and the emScon emulator on a config's simulated cell (``emscon_cell``). Imports
plan, config, drivers and robocal."""
from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "devices": ("open_devices",),
    "eta": ("RunEta", "budget_duration_s", "estimate_duration_s", "grid_duration_s", "point_times_s"),
    "log_events": ("ExitStatus", "ForecastEvent", "LogEvent"),
    "log_reader": ("LOG_NAME", "LogContents", "completed_point_ids", "read_log"),
    "log_records": ("NestRecord", "OPTIONAL_FIELDS", "PointRecord", "Record", "SETS", "check_records"),
    "log_writer": ("RunLog",),
    "output_dirs": ("Claim", "RUN", "check_campaign_dir", "check_dir", "check_file", "check_finished_run",
                    "is_run_dir", "live_check", "not_started", "read_marker", "release_locks", "source_key"),
    "resume_checks": ("check_resume",),
    "runner": ("RunOutcome", "closing_on_error", "pending"),
    "session": ("RunProgress", "continue_clock", "default_run_dir", "make_runner", "observe_points", "open_log",
                "unique_path"),
    "traceability": ("check_identity", "device_identity", "identification", "identity_changes", "run_logging",
                     "software_version"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
