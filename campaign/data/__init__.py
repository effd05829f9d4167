"""Measured data in memory: the ``Dataset`` shared by the CSV, the log and the calibration, the interchange CSV
(``interchange_csv``: the format, ``read_csv``, ``write_csv``; their steps in ``interchange_reader``,
``interchange_blocks`` (reading in blocks) and ``interchange_writer``), the durable log as a dataset
(``log_dataset``), ``load_source(path)`` for a run directory or a CSV, and ``memory_check`` (the early size check
before anything is read). Imports run (log records), config and robocal."""
from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "dataset": ("Dataset",),
    "importers": ("import_target_dif",),
    "interchange_csv": ("write_csv",),
    "log_dataset": ("dataset_from_log",),
    "memory_check": ("CALIBRATE", "SELECT", "Need", "check_memory"),
    "source": ("csv_provenance", "load_source"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
