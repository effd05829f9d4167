"""Measured data in memory: the ``Dataset`` shared by the CSV, the log and the calibration, the interchange CSV
(``interchange_csv``: the format, ``read_csv``, ``write_csv``; their steps in ``interchange_reader``,
``interchange_blocks`` (reading in blocks) and ``interchange_writer``), the durable log as a dataset (``log_dataset``), and ``load_source(path)`` for a run directory
or a CSV. Imports run (log records), config and robocal."""
