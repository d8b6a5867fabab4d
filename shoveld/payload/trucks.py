"""Passes grouped into trucks, and the 10/10/20 overload rule of haul trucks.

The rule (as mines apply it to a fleet): the mean load should not exceed the
target, no more than 10 % of loads may exceed 110 % of target, and no load may
exceed 120 % of target.

A pass not weighed (the engine refused it: no valid inputs, a laser off the handle)
still went into the truck, so a truck with one has a load known only from below: its
weighed total. Such a truck is not called under or within its target, and the rule
does not judge it, except that a weighed total already above 120 % is an overload.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from shoveld.words import n_of

STATUSES = ("under", "ok", "incomplete", "over_110", "over_120")
"""A truck's ``status``: ``incomplete`` is a truck with a pass not weighed whose weighed
total is not above 110 % (its load is not known); ``over_*`` hold whatever was not
weighed, as it can only add."""


@dataclass
class Truck:
    index: int
    target_kg: float
    passes: list[dict[str, Any]] = field(default_factory=list)

    @property
    def total_kg(self) -> float:
        """The weighed passes' sum: the truck's load when :attr:`not_weighed` is 0, else
        a lower bound of it."""
        return sum(p["payload_kg"] for p in self.passes if p.get("valid", True))

    @property
    def std_kg(self) -> float:
        return sum(p["std_kg"] ** 2 for p in self.passes if p.get("valid", True)) ** 0.5

    @property
    def not_weighed(self) -> int:
        """Passes loaded into the truck that the engine did not weigh."""
        return sum(1 for p in self.passes if not p.get("valid", True))

    @property
    def status(self) -> str:
        """under (< 90 %), ok, incomplete (a pass not weighed), over_110 (allowed for 10 %
        of loads), over_120 (never); see :data:`STATUSES`."""
        r = self.total_kg / self.target_kg
        if r > 1.2:
            return "over_120"
        if r > 1.1:
            return "over_110"
        if self.not_weighed:
            return "incomplete"
        return "under" if r < 0.9 else "ok"

    def as_dict(self) -> dict[str, Any]:
        return {"truck": self.index, "passes": len(self.passes),
                "total_kg": round(self.total_kg, 1), "std_kg": round(self.std_kg, 1),
                "target_kg": self.target_kg,
                "fill_pct": round(100.0 * self.total_kg / self.target_kg, 1),
                "status": self.status, "invalid_passes": self.not_weighed}


def rule_101020(trucks: list[Truck]) -> dict[str, Any]:
    """Fleet summary against the 10/10/20 rule.

    The mean and the share over 110 % are over the trucks whose every pass was weighed
    (``trucks``); ``not_judged`` counts the others. ``over_120`` counts every truck whose
    weighed total is above 120 %, judged or not: a pass not weighed can only add to it.
    """
    judged = [t for t in trucks if not t.not_weighed]
    over120 = sum(1 for t in trucks if t.total_kg > 1.2 * t.target_kg)
    out: dict[str, Any] = {"trucks": len(judged), "not_judged": len(trucks) - len(judged),
                           "over_120": over120}
    if not judged:
        return {**out, "compliant": over120 == 0}
    loads = [t.total_kg for t in judged]
    target = judged[0].target_kg
    over110 = sum(1 for x in loads if x > 1.1 * target)
    mean = sum(loads) / len(loads)
    return {**out, "mean_kg": round(mean, 1), "target_kg": target,
            "mean_pct": round(100 * mean / target, 1),
            "over_110_pct": round(100.0 * over110 / len(loads), 1),
            "compliant": over120 == 0 and over110 <= 0.1 * len(loads) and mean <= target}


def rule_summary(rule: dict[str, Any], closed: bool = True) -> str:
    """The rule's figures in one line for people (``shoveld passes``, ``estimate``), with
    the trucks it could not judge, or why it judged none. ``closed``: the trucks judged
    are the closed ones (the pass log's), and the line says so."""
    nj = int(rule.get("not_judged") or 0)
    skipped = f"{n_of(nj, 'truck', 'trucks')} with a pass not weighed not judged" if nj else ""
    verdict = "compliant" if rule.get("compliant", True) else "NOT compliant"
    if not rule.get("trucks"):
        if not skipped:
            return "no closed truck" if closed else "no truck"
        over = (f", {rule['over_120']} over 120 % by their weighed passes alone -> {verdict}"
                if rule.get("over_120") else "")
        return f"no truck judged: {skipped}{over}"
    word = ("closed truck", "closed trucks") if closed else ("truck", "trucks")
    return (f"{n_of(rule['trucks'], *word)}: mean "
            f"{rule['mean_pct']} % of target, {rule['over_110_pct']} % over 110 %, "
            f"{rule['over_120']} over 120 %" + (f"; {skipped}" if skipped else "")
            + f" -> {verdict}")


def passes_words(d: dict[str, Any]) -> tuple[str, str]:
    """A truck message's passes in words, "3 passes (1 not weighed)", and what goes before
    its total: "at least " with a pass not weighed (the total is a lower bound), else ""."""
    n = int(d.get("invalid_passes") or 0)
    return (n_of(d.get("passes") or 0, "pass", "passes") + (f" ({n} not weighed)" if n else ""),
            "at least " if n else "")


def truck_line(d: dict[str, Any]) -> str:
    """A truck of :meth:`Truck.as_dict` in words: "4 passes, 87300 kg of 240000 kg (36.4
    %), ok"; with a pass not weighed its total is "at least" and the count says so."""
    passes, least = passes_words(d)
    return (f"{passes}, {least}{d['total_kg']:.0f} kg of {d['target_kg']:.0f} kg "
            f"({d['fill_pct']:.1f} %), {d['status']}")
