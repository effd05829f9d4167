"""Measured data in memory: the ``Dataset`` shared by the CSV, the log and the calibration, the interchange CSV
reader and writer, the durable log as a dataset (``log_dataset``), and ``load_source(path)`` for a run directory
or a CSV. Imports run (log records), config and robocal."""
