"""``campaign.process`` loaded on first use: a campaign that is interrupted (or only measures) starts without
importing the calibration numerics and their SciPy modules (about half a second of every ``campaign run``)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .process import Processed
else:
    Processed = Any


def process(*args: Any, **kwargs: Any) -> Any:
    """:func:`campaign.process.process`, imported now."""
    from .process import process as _process
    return _process(*args, **kwargs)


def write_outputs(*args: Any, **kwargs: Any) -> Any:
    """:func:`campaign.process.write_outputs`, imported now."""
    from .process import write_outputs as _write_outputs
    return _write_outputs(*args, **kwargs)
