"""What the cab and office pages show, built from the daemon's Zenoh messages.

The terminal cab's :class:`~shoveld.cli.cab.CabState` keeps the messages (and the
catch-up from ``status``); :class:`ScreenState` adds the joints, the time each shovel
was last heard, and turns it all into one JSON snapshot per shovel with the figures a
person reads: remaining, the last-pass hint, warnings in words. The pages only draw
the snapshot, so everything they say is computed (and tested) here.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from shoveld.cli.cab import CabState, ShovelView
from shoveld.words import n_of

SILENT_AFTER_S = 3.0
"""A shovel not heard from for this long is shown as silent (health comes every 1 s)."""
RECENT_PASSES = 10
"""Passes of this shovel the last-pass hint takes its typical pass size from."""
NO_SHIFT: dict[str, float] = {"trucks": 0, "passes": 0, "kg": 0.0, "not_weighed": 0}
"""A shift with no closed truck seen yet."""


def last_pass_hint(total_kg: float, target_kg: float, recent_kg: list[float],
                   not_weighed: int = 0) -> dict[str, Any]:
    """What the next pass should carry to top the truck off without passing 110 %.

    From the remaining load and this shovel's recent pass sizes: when one typical pass
    (or less) is left, the last pass should carry the remaining, and at most what keeps
    the truck at 110 %; otherwise the passes still needed and the size of each.

    ``not_weighed`` passes are in the truck but not in ``total_kg``: the hint counts each
    as a typical pass and says so, as a hint that left them out would ask for more than
    the truck can take; with no typical pass yet it says the load is not known.
    """
    typical = sum(recent_kg) / len(recent_kg) if recent_kg else math.nan
    known = math.isfinite(typical) and typical > 0.0
    note = ""
    if not_weighed:
        if total_kg >= target_kg:  # full by the weighed passes alone: nothing to count
            return {"kind": "full", "text": "Truck full: send it",
                    "remaining_kg": target_kg - total_kg, "passes_left": 0}
        if not known:
            return {"kind": "unknown", "remaining_kg": None, "passes_left": None,
                    "text": f"{n_of(not_weighed, 'pass', 'passes')} not weighed: "
                            "the truck's load is not known"}
        total_kg += not_weighed * typical
        note = (f", counting the {'pass' if not_weighed == 1 else 'passes'} not weighed "
                f"as {typical / 1000:.1f} t" + (" each" if not_weighed > 1 else ""))
    remaining = target_kg - total_kg
    limit = 1.10 * target_kg - total_kg
    if remaining <= 0.0:
        return {"kind": "full", "text": "Truck full: send it" + note,
                "remaining_kg": remaining, "passes_left": 0}
    if not known:
        return {"kind": "unknown", "text": f"{remaining / 1000:.1f} t to go",
                "remaining_kg": remaining, "passes_left": None}
    left = max(1, math.ceil(remaining / typical - 0.1))
    if left == 1:
        return {"kind": "last", "remaining_kg": remaining, "passes_left": 1,
                "carry_kg": remaining, "max_kg": limit,
                "text": f"Last pass: carry {remaining / 1000:.1f} t "
                        f"(at most {limit / 1000:.1f} t)" + note}
    each = remaining / left
    return {"kind": "more", "remaining_kg": remaining, "passes_left": left, "carry_kg": each,
            "text": f"{n_of(left, 'pass', 'passes')} left, about {each / 1000:.1f} t each"
                    + note}


def doubtful_note(passes: list[dict[str, Any]]) -> str | None:
    """What the cab says under this truck's passes when the model did not fit some of them
    (the daemon marks them ``misfit_high``): weighed, and counted in the truck, but their
    weights may be off. Passes are numbered within the truck, as the page lists them."""
    marked = [(i, p.get("misfit")) for i, p in enumerate(passes, start=1)
              if p.get("valid") and p.get("misfit_high")]
    if not marked:
        return None
    if len(marked) == 1:
        i, m = marked[0]
        fit = f" (misfit {m:.1f})" if isinstance(m, (int, float)) else ""
        return f"? pass {i}: the model did not fit it{fit}; its weight may be off"
    numbers = ", ".join(str(i) for i, _ in marked[:-1]) + f" and {marked[-1][0]}"
    return f"? passes {numbers}: the model did not fit them; their weights may be off"


def truck_warning(truck: dict[str, Any] | None) -> dict[str, str] | None:
    """An over-load warning, one for a truck with a pass not weighed (its load is known
    only from below), or an under-load one once the truck is closed."""
    if not truck:
        return None
    status = str(truck.get("status") or "")
    fill = truck.get("fill_pct")
    if status == "over_120":
        return {"level": "alarm", "text": f"OVERLOADED: {fill} % of target (over 120 %)"}
    if status == "over_110":
        return {"level": "warn", "text": f"Over 110 %: {fill} % of target"}
    if status == "incomplete":
        n = int(truck.get("invalid_passes") or 0)
        what = n_of(n, "pass", "passes") if n else "a pass"
        return {"level": "warn",
                "text": (f"Sent off with {what} not weighed: at least {fill} % of target"
                         if truck.get("closed") else
                         f"{what} not weighed: at least {fill} % loaded")}
    if status == "under" and truck.get("closed"):
        return {"level": "warn", "text": f"Left under-loaded: {fill} % of target"}
    return None


class ScreenState(CabState):
    """The cab's state, plus joints and timing, as snapshots for the web pages."""

    keeps_lines = False  # the pages draw everything from the snapshot

    def __init__(self, on_change: Callable[[], None] | None = None) -> None:
        super().__init__()
        self.joints: dict[str, dict[str, Any]] = {}
        self.heard: dict[str, float] = {}
        """Monotonic time each shovel was last heard from."""
        self.recent: dict[str, list[float]] = {}
        self.shift: dict[str, dict[str, float]] = {}
        """Per shovel, passes and tonnes of the trucks closed while this screen ran (used
        when the daemon's truck messages carry no ``shift`` of their own)."""
        self.on_change = on_change
        self.version = 0

    def _changed(self) -> None:
        self.version += 1
        if self.on_change is not None:
            self.on_change()

    def on_message(self, shovel: str, topic: str, msg: dict[str, Any]) -> None:
        self.heard[shovel] = time.monotonic()
        if topic == "joints":
            with self.lock:
                self.view(shovel).alive = True
                self.joints[shovel] = msg
        else:
            super().on_message(shovel, topic, msg)
            with self.lock:
                if topic == "pass" and msg.get("valid") and msg.get("payload_kg") is not None:
                    r = self.recent.setdefault(shovel, [])
                    r.append(float(msg["payload_kg"]))
                    del r[:-RECENT_PASSES]
                if topic == "truck" and msg.get("closed"):
                    s = self.shift.setdefault(shovel, dict(NO_SHIFT))
                    s["trucks"] += 1
                    s["passes"] += int(msg.get("passes") or 0)
                    s["kg"] += float(msg.get("total_kg") or 0.0)
                    s["not_weighed"] += int(msg.get("invalid_passes") or 0)
        self._changed()

    def on_bad_message(self, shovel: str, topic: str, problem: str) -> None:
        super().on_bad_message(shovel, topic, problem)
        self._changed()  # the count is on the page

    def on_status(self, shovel: str, st: dict[str, Any]) -> None:
        self.heard[shovel] = time.monotonic()
        super().on_status(shovel, st)
        with self.lock:
            r = self.recent.setdefault(shovel, [])
            if not r:
                r.extend(float(p["payload_kg"]) for p in st.get("truck_passes") or []
                         if p.get("valid") and p.get("payload_kg") is not None)
        self._changed()

    def on_alive(self, shovel: str, alive: bool) -> None:
        if alive:
            self.heard[shovel] = time.monotonic()
        super().on_alive(shovel, alive)
        self._changed()

    def set_link(self, link: str, detail: str = "") -> None:
        super().set_link(link, detail)
        self._changed()

    def snapshot(self, now: float | None = None) -> dict[str, Any]:
        """Every shovel as the pages draw it (JSON-ready)."""
        now = time.monotonic() if now is None else now
        with self.lock:
            shovels = [self._shovel(v, now) for _, v in sorted(self.shovels.items())]
            return {"time": time.time(), "link": self.link, "link_detail": self.link_detail,
                    "version": self.version, "shovels": shovels}

    def _shift_closed(self, shovel: str, truck: dict[str, Any]) -> dict[str, Any]:
        """Closed trucks this shift: the daemon's count from its pass log when its truck
        message carries one (true however late this screen started), else what was seen.
        ``misfit_high``: its passes the model did not fit, None when the daemon does not
        count them (older than the count, or no ``shift`` at all)."""
        seen = {**self.shift.get(shovel, NO_SHIFT), "misfit_high": None}
        ds = truck.get("shift")
        if not isinstance(ds, dict):
            return seen
        try:
            marked = ds.get("misfit_high")
            return {"trucks": int(ds["trucks"]), "passes": int(ds["passes"]),
                    "kg": float(ds["kg"]), "not_weighed": int(ds.get("not_weighed") or 0),
                    "misfit_high": None if marked is None else int(marked)}
        except (KeyError, TypeError, ValueError):
            return seen

    def _shovel(self, v: ShovelView, now: float) -> dict[str, Any]:
        heard = self.heard.get(v.shovel)
        age = None if heard is None else now - heard
        silent = (not v.alive) or age is None or age > SILENT_AFTER_S
        live = dict(v.live or {})
        valid = bool(live.get("valid")) and live.get("payload_kg") is not None and not silent
        truck = dict(v.truck or {})
        if v.closed and truck and v.closed[-1].get("truck") == truck.get("truck"):
            truck = dict(v.closed[-1])  # the truck was sent off; no new one yet
        target = float(truck.get("target_kg") or 0.0)
        total = float(truck.get("total_kg") or 0.0)
        problems = list(v.problems)
        if silent:
            problems.insert(0, "daemon: stopped (liveliness lost)" if not v.alive else
                            f"daemon: not heard for {age or 0:.0f} s")
        if self.link != "up":
            problems.insert(0, f"link: {self.link} {self.link_detail}".strip())
        if (note := self.refused_note(v.shovel)) is not None:
            problems.append(note)
        shift = self._shift_closed(v.shovel, truck)
        is_open = bool(truck) and not truck.get("closed")
        not_weighed = int(truck.get("invalid_passes") or 0)
        hint = (last_pass_hint(total, target, self.recent.get(v.shovel, []), not_weighed)
                if target and is_open else None)
        passes = [{k: p.get(k) for k in ("pass", "truck", "payload_kg", "std_kg", "valid",
                                          "reason", "end", "misfit", "misfit_high")}
                  for p in v.passes if not truck or p.get("truck") == truck.get("truck")]
        return {
            "shovel": v.shovel, "alive": v.alive and not silent, "silent": silent,
            "age_s": None if age is None else round(age, 1),
            "phase": live.get("phase") if not silent else None,
            "payload_kg": live.get("payload_kg") if valid else None,
            "std_kg": live.get("std_kg") if valid else None,
            "valid": valid,
            # the crowd in doubt since its laser's gap (or change of target): the pass
            # under way is judged at its end, so the number shown now is marked
            "crowd_doubt": live.get("crowd_doubt") if valid else None,
            "truck": truck or None,
            "remaining_kg": hint.get("remaining_kg") if hint else
                            (target - total) if target else None,
            "hint": hint if hint else
                    ({"kind": "closed", "text": f"Truck {truck.get('truck')} sent off: "
                      "waiting for the next truck"} if truck.get("closed") else None),
            "warning": truck_warning(truck),
            "passes": passes,
            "doubt": doubtful_note(passes),
            "closed": [{k: c.get(k) for k in ("truck", "passes", "total_kg", "target_kg",
                                               "fill_pct", "status", "invalid_passes")}
                       for c in v.closed[-5:]][::-1],
            "rule": (v.closed[-1].get("rule_10_10_20") if v.closed
                     else truck.get("rule_10_10_20")),
            "shift": {"trucks": shift["trucks"] + int(is_open),
                      "passes": shift["passes"] + (int(truck.get("passes") or 0)
                                                   if is_open else 0),
                      "kg": shift["kg"] + (total if is_open else 0.0),
                      "not_weighed": shift["not_weighed"] + (not_weighed if is_open else 0),
                      "misfit_high": None if shift["misfit_high"] is None else
                      shift["misfit_high"] + (sum(bool(p["valid"] and p["misfit_high"])
                                                  for p in passes) if is_open else 0)},
            "joints": self.joints.get(v.shovel),
            "problems": problems,
        }
