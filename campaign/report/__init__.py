"""Showing results, computing no calibration: terminal tables (``terminal``, ``diagnosis_text``), the self-contained
HTML report and its figures (``html``, ``html_figures``, ``templates/``), diagnosis plots, the ISO 9283
characteristics of an acceptance run (``iso9283``) and model export (``export``: URDF, DH tables). Imports
calibrate, correct, data, run, plan, config and robocal."""
