"""``load_source(path)``: a run directory (its durable log) or an interchange CSV as a ``Dataset``."""
from __future__ import annotations

import os
from pathlib import Path

from campaign.errors import DataError

from .dataset import Dataset
from .interchange_csv import read_csv
from .log_dataset import dataset_from_log


def load_source(source: str | os.PathLike) -> Dataset:
    """A run directory (its log.jsonl) or an interchange CSV; DataError when it is neither."""
    from campaign.run.log_reader import read_log

    path = Path(source)
    if not path.exists():
        raise DataError(str(path), "no such file or run directory")
    return dataset_from_log(read_log(path)) if path.is_dir() else read_csv(path)
