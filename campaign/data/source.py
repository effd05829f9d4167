"""``load_source(path)``: a run directory (its durable log) or an interchange CSV as a ``Dataset``, the one place
where "source -> dataset" is decided (``campaign run`` at its end, ``reprocess``, ``diagnose``)."""
from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path

from campaign.errors import DataError
from campaign.run.log_reader import LogContents, read_log

from .dataset import Dataset
from .interchange_csv import read_csv
from .log_dataset import dataset_from_log
from .memory_check import CALIBRATE, Need, check_memory


@dataclass(frozen=True, eq=False)
class Source:
    """The measured data of a source and, for a run directory, the log it came from (hardware identification,
    ``plan.stop`` decisions; None for a CSV)."""
    dataset: Dataset
    contents: LogContents | None = None


def load_source(source: str | os.PathLike, need: Need = CALIBRATE) -> Source:
    """A run directory (its log.jsonl, converted by :func:`dataset_from_log`) or an interchange CSV; DataError
    when the path does not exist, or when its rows need more memory than this machine allows the command (``need``,
    :mod:`campaign.data.memory_check`: checked before anything is read), a FileNotFoundError naming log.jsonl for a
    directory without a log."""
    path = Path(source)
    if not path.exists():
        raise DataError(str(path), "no such file or run directory")
    check_memory(path, need)
    if not path.is_dir():
        return Source(read_csv(path))
    contents = read_log(path)
    return Source(dataset_from_log(contents), contents)


def csv_provenance(dataset: Dataset) -> str:
    """Where the rows of data without a run log came from, for its report: the CSV's provenance line (``campaign
    import``: "imported from FILE ...") or the file itself, and that no device is recorded with them."""
    return f"{dataset.provenance or f'read from the interchange CSV {dataset.source}'}; devices not recorded"
