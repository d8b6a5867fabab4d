"""Column specification of the signals table (format ``shovel-signals/1``).

One place owns the column order, units and plausible ranges so that the reader,
the writer, the simulator and the daemon agree; the ranges catch unit mistakes
(a crowd in millimetres, currents in kA) at the door.
"""

from __future__ import annotations

from dataclasses import dataclass

FORMAT_NAME = "shovel-signals/1"


@dataclass(frozen=True)
class Column:
    """A signals-table column: its unit and the physically plausible range."""

    name: str
    unit: str
    lo: float
    hi: float
    doc: str


COLUMNS: tuple[Column, ...] = (
    Column("time_s", "s", -1e9, 1e10, "sample time, strictly increasing"),
    Column("handle_deg", "deg", -90.0, 90.0, "dipper handle angle above the true horizontal"),
    Column("crowd_m", "m", 0.0, 20.0, "saddle-block pivot to dipper bail along the handle"),
    Column("swing_deg", "deg", -720.0, 720.0, "swing angle from the configured zero"),
    Column("boom_deg", "deg", 20.0, 70.0, "boom angle above the machinery deck"),
    Column("hoist1_a", "A", -6000.0, 6000.0, "hoist motor 1 armature current"),
    Column("hoist2_a", "A", -6000.0, 6000.0, "hoist motor 2 armature current"),
    Column("hoist_field_a", "A", -200.0, 200.0, "hoist field current (series fields)"),
    Column("crowd_a", "A", -6000.0, 6000.0, "crowd motor armature current"),
    Column("crowd_field_a", "A", -200.0, 200.0, "crowd field current"),
    Column("swing_a", "A", -6000.0, 6000.0, "swing motors armature current"),
    Column("swing_field_a", "A", -200.0, 200.0, "swing field current"),
    Column("roll_deg", "deg", -30.0, 30.0, "machinery-house roll (cab inclinometer)"),
    Column("pitch_deg", "deg", -30.0, 30.0, "machinery-house pitch (cab inclinometer)"),
    Column("payload_kg", "kg", -1000.0, 150000.0, "scale-verified payload where known"),
)

COLUMN_NAMES: tuple[str, ...] = tuple(c.name for c in COLUMNS)
BY_NAME: dict[str, Column] = {c.name: c for c in COLUMNS}
KNOWN_META_KEYS = ("format", "sample_rate_hz", "shovel", "known_payload_kg")
