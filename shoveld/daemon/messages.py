"""The daemon's Zenoh messages as the screens read them, checked on arrival.

A cab or the office takes a pass's payload, a truck's total and a live estimate from
JSON it did not write: another version of the daemon, or a bug, can send a field of
another type. Until 2026-11-30 such a message reached the screens' formatting and
ended in a traceback in Zenoh's callback (``Unknown format code 'f' for object of type
'str'``), the message lost without a word, or was shown ("pass a truck None"). Here
each field the screens read has its kind; a message with a field of another kind is
refused whole, with what is wrong, and the screens count it. Fields they do not read
are left alone, and a field may be absent (the screens have a default for each).
"""

from __future__ import annotations

import math
from typing import Any

NUMBERS = frozenset({"payload_kg", "std_kg", "total_kg", "target_kg", "fill_pct", "misfit",
                     "time", "start", "end", "start_s", "end_s"})
"""Finite numbers (or null: the daemon writes a value it has not as null)."""
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
TEXTS = frozenset({"reason", "status", "phase"})


def _kind_ok(key: str, v: Any) -> str | None:
    """What ``v`` should have been for ``key``, if it is not; None if it is, or if the
    screens do not read ``key``."""
    if v is None:
        return None
    if key in NUMBERS:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            return "a finite number"
        if key in TIMES and not 0.0 <= v <= LATEST:
            return "a time from 1970 to 9999 (Unix seconds)"
    elif key in COUNTS:
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            return "a whole number, 0 or more"
    elif key in FLAGS:
        if not isinstance(v, bool):
            return "true or false"
    elif key in TEXTS:
        if not isinstance(v, str):
            return "a text"
    elif key == "problems":
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            return "a list of texts"
    return None


def message_problem(msg: Any) -> str | None:
    """Why the screens cannot take ``msg`` (one topic's message, or one part of a
    ``status`` answer), in a few words; None if they can."""
    if not isinstance(msg, dict):
        return f"a JSON {type(msg).__name__} where an object was expected"
    for k, v in msg.items():
        expected = _kind_ok(k, v)
        if expected is not None:
            text = repr(v)
            return f"key {k!r} is {text if len(text) <= 40 else text[:37] + '...'}, not " \
                   f"{expected}"
    return None


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
