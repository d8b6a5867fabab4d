"""One aligned sample of every signal: the unit that flows from sources into the loop.

A ``Sample`` is one row of a signals table. Offline it comes from a table, live
it is assembled by the daemon from the freshest driver readings aligned to the
tick time; the engine cannot tell the two apart, which is the point.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, fields

from shoveld.signals.columns import COLUMN_NAMES
from shoveld.signals.table import SignalsTable


@dataclass(slots=True)
class Sample:
    """Signals at one instant; NaN marks a value that is unknown or invalid."""

    time_s: float
    handle_deg: float = math.nan
    crowd_m: float = math.nan
    swing_deg: float = math.nan
    boom_deg: float = math.nan
    hoist1_a: float = math.nan
    hoist2_a: float = math.nan
    hoist_field_a: float = math.nan
    crowd_a: float = math.nan
    crowd_field_a: float = math.nan
    swing_a: float = math.nan
    swing_field_a: float = math.nan
    roll_deg: float = math.nan
    pitch_deg: float = math.nan
    payload_kg: float = math.nan
    invalid: frozenset[str] = field(default_factory=frozenset)
    """Names of signals whose source is missing, stale or faulty at this instant, and
    :data:`CROWD_TARGET_CHANGED` at the instant the crowd's laser changed target."""

    def as_row(self) -> list[float]:
        return [getattr(self, n) for n in COLUMN_NAMES]


CROWD_TARGET_CHANGED = "crowd_target_changed"
"""Not a signal: in ``Sample.invalid`` at the tick where the crowd's laser took something
else in its beam as its target (``drivers.base.TARGETS_TAKEN`` grew). The
distances before and after it are not of the same thing, so the engine does not weigh
the pass it falls in (from the dig's start to the dump)."""

SIGNAL_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(Sample) if f.name != "invalid")
assert SIGNAL_FIELDS == COLUMN_NAMES, "Sample fields must follow the signals-table columns"


SAMPLE_CHUNK = 4096
"""Rows turned into Python floats at a time. The whole table at once cost 24-32 bytes a
cell beside the table's own 8: 75 MiB per hour of 50 Hz signals, most of what
``shoveld estimate`` held (bench/estimate_memory.py)."""


def samples_from_table(table: SignalsTable) -> Iterator[Sample]:
    """Rows of a table as samples, in time order."""
    arrays = [table.columns[n] for n in COLUMN_NAMES]
    for a in range(0, len(table), SAMPLE_CHUNK):
        cols = [c[a:a + SAMPLE_CHUNK].tolist() for c in arrays]
        for row in zip(*cols, strict=True):
            yield Sample(*row)
