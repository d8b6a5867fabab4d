"""argparse types for the commands' numeric options, and for the words of Zenoh keys.

A value out of its range (a negative load, ``nan`` seconds, a machine seed of -3) is
refused by argparse with the option named and the range expected, in one line, before
any work: until 2026-11-30 such values went through and were silently used or ended in
a traceback far from the option. Light on purpose: every command's ``--help`` loads it.
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable

from shoveld import keys


def _range_words(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool,
                 integer: bool) -> str:
    kind = "a whole number" if integer else "a number"
    fmt = "{:d}" if integer else "{:g}"
    parts = []
    if lo is not None:
        parts.append(("above " if lo_open else "at least ") + fmt.format(lo))
    if hi is not None:
        parts.append(("below " if hi_open else "at most ") + fmt.format(hi))
    return kind + (" " + " and ".join(parts) if parts else "")


def number(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
           hi_open: bool = False, integer: bool = False, unit: str = "",
           hint: str = "") -> Callable[[str], float]:
    """A type for ``add_argument``: a finite number within [lo, hi] (``lo_open``: above
    lo, ``hi_open``: below hi), a whole one with ``integer``; ``unit`` is said after the
    range ("seconds", "kg"), and ``hint`` after that (another option that may be meant)."""
    expected = (_range_words(lo, hi, lo_open, hi_open, integer) + (f" ({unit})" if unit else "")
                + (f"; {hint}" if hint else ""))

    def parse(text: str) -> float:
        try:
            x: float = int(text) if integer else float(text)
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and (lo is None or (x > lo if lo_open else x >= lo))
                and (hi is None or (x < hi if hi_open else x <= hi))):
            raise argparse.ArgumentTypeError(f"{text!r}: expected {expected}")
        return x

    return parse


SECONDS = number(0.0, lo_open=True, unit="seconds")
"""A duration that must pass: above zero seconds."""
SECONDS_OR_ZERO = number(0.0, unit="seconds")
"""A wait that may be skipped: zero seconds or more."""
KG = number(0.0, lo_open=True, unit="kg")
"""A mass that must be there (a truck's target)."""
KG_OR_ZERO = number(0.0, unit="kg")
"""A mass that may be zero (a load, an empty dipper)."""
COUNT = number(1, integer=True)
"""How many of something, one at least."""
SEED = number(0, integer=True)
"""A random generator's seed: numpy takes whole numbers of zero or more."""
ORDER = number(2, 20, integer=True)
"""A Savitzky-Golay fit's order: 2 at least, as the model needs accelerations; at most
20 (order 30 left the hoist's pull per ampere with a standard error of 55 %, against
0.12 % at the default 7, on a simulated calibration)."""


def key_chunk(rx: re.Pattern[str], expected: str) -> Callable[[str], str]:
    """A type for a Zenoh key's words: ``rx`` (one of :mod:`shoveld.keys`, which the whole
    text must match), ``expected`` said in the refusal."""

    def parse(text: str) -> str:
        if not rx.fullmatch(text):
            raise argparse.ArgumentTypeError(f"{text!r}: expected {expected}")
        return text

    return parse


SHOVEL_ID = key_chunk(keys.NAME,
                      "1-64 letters, digits, '_', '.', '-' (a shovel's id, as shovel.id)")
"""A shovel's id on Zenoh: one plain key chunk, as the config's ``shovel.id`` (a '/' or a
'*' in it published under another shovel's keys, or under none a cab reads)."""
SHOVEL_OR_ALL = key_chunk(re.compile(rf"{keys.NAME.pattern}|\*"),
                          "a shovel's id (1-64 letters, digits, '_', '.', '-') or * for all")
"""The shovels a screen shows: one id, or ``*``."""
KEY_PREFIX = key_chunk(keys.PREFIX,
                       "a plain key expression, as zenoh.prefix (e.g. shovel or site1/shovel)")
"""The key prefix of a site's shovels, as the config's ``zenoh.prefix``."""
