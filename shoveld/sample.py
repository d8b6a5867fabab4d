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
    """Names of signals whose source is missing, stale or faulty at this instant."""

    def as_row(self) -> list[float]:
        return [getattr(self, n) for n in COLUMN_NAMES]


SIGNAL_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(Sample) if f.name != "invalid")
assert SIGNAL_FIELDS == COLUMN_NAMES, "Sample fields must follow the signals-table columns"


def samples_from_table(table: SignalsTable) -> Iterator[Sample]:
    """Rows of a table as samples, in time order."""
    cols = [table.columns[n].tolist() for n in COLUMN_NAMES]
    for row in zip(*cols, strict=True):
        yield Sample(*row)
