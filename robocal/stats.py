"""Error statistics of seed 000 Table 3: max / mean / RMS of the 3-D position error."""
from __future__ import annotations

from dataclasses import dataclass, asdict

import numpy as np


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of 3-D position errors in mm over n points."""
    max_mm: float
    mean_mm: float
    rms_mm: float
    n: int

    def to_dict(self) -> dict:
        return asdict(self)


def error_stats(err_mm: np.ndarray) -> ErrorStats:
    """err_mm (N, 3) measured - predicted -> ErrorStats of |err| (NaN stats for N = 0)."""
    e = np.linalg.norm(np.atleast_2d(np.asarray(err_mm, float)).reshape(-1, 3), axis=1)
    if len(e) == 0:
        return ErrorStats(float("nan"), float("nan"), float("nan"), 0)
    return ErrorStats(float(e.max()), float(e.mean()), float(np.sqrt(np.mean(e**2))), int(len(e)))
