"""The daemon's Zenoh messages as the screens read them, checked on arrival.

A cab or the office takes a pass's payload, a truck's total and a live estimate from
JSON it did not write: another version of the daemon, or a bug, can send a field of
another type. Until 2026-11-30 such a message reached the screens' formatting and
ended in a traceback in Zenoh's callback (``Unknown format code 'f' for object of type
'str'``), the message lost without a word, or was shown ("pass a truck None"). Here
each field the screens read has its kind; a message with a field of another kind is
refused whole, with what is wrong, and the screens count it. Fields they do not read
are left alone, and a field may be absent (the screens have a default for each). The
lists are by hand; ``tests/daemon/test_cab.py::test_every_field_the_screens_read_is_checked``
feeds the screens the daemon's messages and fails on a field they read that is not here.
"""

from __future__ import annotations

import math
from typing import Any

NUMBERS = frozenset({"payload_kg", "std_kg", "total_kg", "target_kg", "fill_pct", "misfit",
                     "time", "start", "end", "start_s", "end_s",
                     "handle_deg", "crowd_m", "swing_deg", "boom_deg"})
"""Finite numbers (or null: the daemon writes a value it has not as null); the last four
are the joints the cab page draws the arm from (a joint as text stopped its drawing,
and what is drawn after it, until 2026-12-02)."""
TIMES = frozenset({"time", "start", "end"})
"""Of the numbers, the wall-clock ones (Unix seconds): from 1970 to 9999, as a screen
writes them as dates."""
LATEST = 253402128000.0
"""9999-12-30T00:00:00 UTC: the last time whose date can be written in year 9999 (a
day short of its end, for any time zone); ``shoveld passes`` and ``report`` take their
``--since`` and ``--until`` up to it too."""
COUNTS = frozenset({"pass", "truck", "passes", "invalid_passes", "samples"})
"""Whole numbers, 0 or more."""
FLAGS = frozenset({"valid", "closed", "misfit_high"})
LISTS = frozenset({"problems", "invalid"})
"""Lists of texts: a health message's problems, and the joints' inputs not valid (the
cab page gets the joints message whole)."""
TEXTS = frozenset({"reason", "status", "phase", "crowd_doubt"})
PARTS: dict[str, dict[str, str]] = {
    "shift": {"window_h": "number", "trucks": "count", "passes": "count", "kg": "number",
              "not_weighed": "count", "misfit_high": "count"},
    "rule_10_10_20": {"window_h": "number", "trucks": "count", "not_judged": "count",
                      "over_120": "count", "mean_kg": "number", "target_kg": "number",
                      "mean_pct": "number", "over_110_pct": "number", "compliant": "flag"},
}
"""A truck message's objects the screens read (the shift so far, the 10/10/20 rule),
with their fields' kinds: until 2026-12-02 they went unchecked, and a shift's ``kg`` as
text ended the terminal cab's screen in a traceback. (In ``shift``, ``misfit_high`` is
a count of trucks, not a pass's flag.)"""
_WANT = {"number": "a finite number", "count": "a whole number, 0 or more",
         "flag": "true or false"}


def _is(kind: str, v: Any) -> bool:
    """Whether ``v`` (not None) is of ``kind``: a finite number, a count or a flag."""
    if kind == "flag":
        return isinstance(v, bool)
    if isinstance(v, bool):
        return False
    if kind == "count":
        return isinstance(v, int) and v >= 0
    return isinstance(v, int | float) and math.isfinite(v)


def _kind_ok(key: str, v: Any) -> str | None:
    """What ``v`` should have been for ``key``, if it is not; None if it is, or if the
    screens do not read ``key``."""
    if v is None:
        return None
    if key in NUMBERS:
        if not _is("number", v):
            return _WANT["number"]
        if key in TIMES and not 0.0 <= v <= LATEST:
            return "a time from 1970 to 9999 (Unix seconds)"
    elif key in COUNTS:
        if not _is("count", v):
            return _WANT["count"]
    elif key in FLAGS:
        if not _is("flag", v):
            return _WANT["flag"]
    elif key in TEXTS:
        if not isinstance(v, str):
            return "a text"
    elif key in LISTS:
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            return "a list of texts"
    return None


def message_problem(msg: Any) -> str | None:
    """Why the screens cannot take ``msg`` (one topic's message, or one part of a
    ``status`` answer), in a few words; None if they can."""
    if not isinstance(msg, dict):
        return f"a JSON {type(msg).__name__} where an object was expected"
    for k, v in msg.items():
        if k in PARTS and v is not None:
            if not isinstance(v, dict):
                return f"key {k!r} is {_short(v)}, not an object"
            kinds = PARTS[k]
            for f, x in v.items():
                if f in kinds and x is not None and not _is(kinds[f], x):
                    return f"key '{k}.{f}' is {_short(x)}, not {_WANT[kinds[f]]}"
            continue
        expected = _kind_ok(k, v)
        if expected is not None:
            return f"key {k!r} is {_short(v)}, not {expected}"
    return None


def _short(v: Any) -> str:
    """``v`` as Python writes it, in 40 characters at most."""
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def status_problem(st: Any) -> str | None:
    """:func:`message_problem` of a ``status`` answer's parts the screens read: its
    truck, each of the truck's passes, its live estimate and its problems (its own
    ``truck`` key is the truck's object, not its number)."""
    if not isinstance(st, dict):
        return f"a JSON {type(st).__name__} where an object was expected"
    truck = st.get("truck")
    if truck is not None and (p := message_problem(truck)) is not None:
        return f"its truck: {p}"
    live = st.get("live")
    if live is not None and (p := message_problem(live)) is not None:
        return f"its live estimate: {p}"
    if (expected := _kind_ok("problems", st.get("problems"))) is not None:
        return f"key 'problems' is not {expected}"
    passes = st.get("truck_passes")
    if passes is None:
        return None
    if not isinstance(passes, list):
        return "key 'truck_passes' is not a list"
    for i, one in enumerate(passes):
        if (p := message_problem(one)) is not None:
            return f"its pass {i + 1}: {p}"
    return None
