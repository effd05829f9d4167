"""Measuring on the cell: the devices of a config (``devices``), the runner that moves, measures and logs each point
before the next move (``runner``, ``tracker_quality``, ``traceability``), the durable log and its typed records
(``log_reader``, ``log_writer``, ``log_records``), resume checks, the ETA, one measuring session (``session``: run
directory, log, safety set-up, progress), the output directories every command owns (``output_dirs``: a run
directory is known by its log) and the emScon emulator on a config's simulated cell (``emscon_cell``). Imports
plan, config, drivers and robocal."""
