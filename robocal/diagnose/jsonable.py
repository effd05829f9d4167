"""JSON-ready values of the diagnosis records: numbers never NaN (None instead), numpy scalars and arrays as
Python values."""
from __future__ import annotations

import numpy as np


def json_float(x):
    return None if x is None or not np.isfinite(x) else float(x)


def plain(x):
    """JSON-ready copy: numpy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return json_float(float(x))
    return x
