"""Passes grouped into trucks, and the 10/10/20 overload rule of haul trucks.

The rule (as mines apply it to a fleet): the mean load should not exceed the
target, no more than 10 % of loads may exceed 110 % of target, and no load may
exceed 120 % of target.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class Truck:
    index: int
    target_kg: float
    passes: list[dict[str, Any]] = field(default_factory=list)

    @property
    def total_kg(self) -> float:
        return sum(p["payload_kg"] for p in self.passes if p.get("valid", True))

    @property
    def std_kg(self) -> float:
        return sum(p["std_kg"] ** 2 for p in self.passes if p.get("valid", True)) ** 0.5

    @property
    def status(self) -> str:
        """under (< 90 %), ok, over_110 (allowed for 10 % of loads), over_120 (never)."""
        r = self.total_kg / self.target_kg
        if r > 1.2:
            return "over_120"
        if r > 1.1:
            return "over_110"
        return "under" if r < 0.9 else "ok"

    def as_dict(self) -> dict[str, Any]:
        return {"truck": self.index, "passes": len(self.passes),
                "total_kg": round(self.total_kg, 1), "std_kg": round(self.std_kg, 1),
                "target_kg": self.target_kg,
                "fill_pct": round(100.0 * self.total_kg / self.target_kg, 1),
                "status": self.status,
                "invalid_passes": sum(1 for p in self.passes if not p.get("valid", True))}


def rule_101020(trucks: list[Truck]) -> dict[str, Any]:
    """Fleet summary against the 10/10/20 rule."""
    if not trucks:
        return {"trucks": 0, "compliant": True}
    loads = [t.total_kg for t in trucks]
    target = trucks[0].target_kg
    over110 = sum(1 for x in loads if x > 1.1 * target)
    over120 = sum(1 for x in loads if x > 1.2 * target)
    mean = sum(loads) / len(loads)
    return {"trucks": len(trucks), "mean_kg": round(mean, 1), "target_kg": target,
            "mean_pct": round(100 * mean / target, 1),
            "over_110_pct": round(100.0 * over110 / len(loads), 1), "over_120": over120,
            "compliant": over120 == 0 and over110 <= 0.1 * len(loads) and mean <= target}
