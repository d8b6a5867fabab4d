"""The figures of a shift report, from the pass log's rows (``persist.read_passes``).

Kept apart from the HTML so every number a supervisor reads is computed once and
tested directly.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from shoveld.payload.misfit import misfit_high
from shoveld.payload.trucks import Truck, rule_101020

EXCHANGE_GAP_S = 120.0
"""Passes further apart than this are not one cycle after the other (a truck exchange,
a break): their interval is not a cycle time."""


_NUMBER = re.compile(r"\d+(?:[.,]\d+)*")


def reason_kind(reason: str) -> str:
    """A reason with its numbers as N, so that the passes not weighed for one cause are
    counted together ("the crowd laser changed target N s into the pass")."""
    return _NUMBER.sub("N", reason) if reason else "unknown"


@dataclass
class ShiftFigures:
    since: float
    until: float
    passes: list[dict[str, Any]]
    trucks: list[dict[str, Any]] = field(default_factory=list)
    rule: dict[str, Any] = field(default_factory=dict)
    hours: list[tuple[float, float, int]] = field(default_factory=list)
    """(hour start, tonnes of valid passes that ended in it, passes)."""
    cycle_s: list[float] = field(default_factory=list)
    invalid: list[dict[str, Any]] = field(default_factory=list)
    reasons: Counter[str] = field(default_factory=Counter)
    """Passes not weighed by the kind of reason (:func:`reason_kind`)."""
    misfits: list[float] = field(default_factory=list)
    """The recorded misfits (a pass log written before 2026-11-29 has none)."""
    misfit_high: list[dict[str, Any]] = field(default_factory=list)
    """Passes whose misfit is above ``MISFIT_WARN``: the model did not fit them."""
    empties: list[dict[str, Any]] | None = None
    """The empty dipper weighed on the returns (``persist.read_empties``); None: the pass
    log records none (written before 2026-11-29's schema 3)."""
    calibrations: list[tuple[str, int, int | None]] = field(default_factory=list)
    """What each params the daemon ran with said of their own calibration, with the first
    and last pass weighed with them (``persist.read_calibrations``); only those that said
    something."""

    def calibration_passes(self, first: int, last: int | None) -> list[int]:
        """This period's passes from ``first`` to ``last`` (None: to the end)."""
        return [int(p["pass"]) for p in self.passes
                if int(p["pass"]) >= first and (last is None or int(p["pass"]) <= last)]

    @property
    def empty_beyond(self) -> list[dict[str, Any]]:
        """The checks after which the daemon held the median of the last returns beyond
        its level (it said so on health while it lasted)."""
        return [e for e in self.empties or [] if e["beyond"]]

    @property
    def valid_kg(self) -> list[float]:
        return [float(p["payload_kg"]) for p in self.passes
                if p["valid"] and p["payload_kg"] is not None]

    @property
    def total_kg(self) -> float:
        return sum(self.valid_kg)


def shift_figures(rows: list[dict[str, Any]], since: float | None = None,
                  until: float | None = None,
                  empties: list[dict[str, Any]] | None = None,
                  calibrations: list[tuple[str, int, int | None]] | None = None
                  ) -> ShiftFigures:
    """Trucks against their targets, the 10/10/20 rule over the closed ones, tonnes per
    hour, cycle times and invalid passes; the misfits, and the empty-dipper checks."""
    ends = [float(r["end"]) for r in rows]
    since = min(ends) if since is None and ends else (since or 0.0)
    until = max(ends) if until is None and ends else (until or 0.0)
    f = ShiftFigures(since, until, rows, empties=empties, calibrations=list(calibrations or []))
    by_truck: dict[int, Truck] = {}
    closed: dict[int, bool] = {}
    for r in rows:
        t = by_truck.setdefault(int(r["truck"]),
                                Truck(int(r["truck"]), float(r["truck_target_kg"] or 1.0)))
        t.passes.append({"payload_kg": r["payload_kg"], "std_kg": r["std_kg"] or 0.0,
                         "valid": r["valid"]})
        closed[int(r["truck"])] = bool(r["truck_closed"])
    for n, t in sorted(by_truck.items()):
        d = t.as_dict()
        d["closed"] = closed[n]
        f.trucks.append(d)
    f.rule = rule_101020([t for n, t in sorted(by_truck.items()) if closed[n]])
    if rows:
        h0 = math.floor(since / 3600.0) * 3600.0
        n_hours = max(1, math.ceil((until - h0) / 3600.0 + 1e-9))
        kg = [0.0] * n_hours
        count = [0] * n_hours
        for r in rows:
            k = min(n_hours - 1, int((float(r["end"]) - h0) // 3600))
            count[k] += 1
            if r["valid"] and r["payload_kg"] is not None:
                kg[k] += float(r["payload_kg"])
        f.hours = [(h0 + 3600.0 * k, kg[k] / 1000.0, count[k]) for k in range(n_hours)]
    for a, b in zip(rows, rows[1:], strict=False):
        gap = float(b["end"]) - float(a["end"])
        if a["truck"] == b["truck"] and 0 < gap <= EXCHANGE_GAP_S:
            f.cycle_s.append(gap)
    f.invalid = [r for r in rows if not r["valid"]]
    f.reasons = Counter(reason_kind(str(r["reason"] or "")) for r in f.invalid)
    f.misfits = [float(r["misfit"]) for r in rows if r.get("misfit") is not None]
    f.misfit_high = [r for r in rows if misfit_high(r.get("misfit"))]
    return f
