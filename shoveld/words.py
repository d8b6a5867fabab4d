"""Counts in the words a person reads: "1 pass", "2 passes", "1 truck", "0 samples".

Every layer that writes text for an operator, a field engineer or a supervisor (the
commands, the plots, the shift report, the diagnosis, the daemon's health problems,
the web pages' snapshot) says its counts the same way, so the helper lives here, at
the top of the package, importing nothing: a plot or the report writer can use it
without pulling in the command-line layer. (The web pages do the same in
``shoveld/web/static/common.js``, ``screen.n``.)

Only text for people goes through it; JSON keys, CSV headers and the fields of the
Zenoh messages keep their fixed names.
"""

from __future__ import annotations


def n_of(k: object, one: str, many: str) -> str:
    """``k`` with the singular noun when it is exactly one, else the plural.

    ``one`` and ``many`` are given whole rather than built with a suffix, because the
    nouns here do not share one rule ("pass"/"passes", "truck"/"trucks") and a phrase
    may carry an adjective ("verified pass"). ``k`` is printed as given (an ``int``
    usually; a value read from a message may be ``None`` and then reads "None ...",
    as it did before).
    """
    return f"{k} {one if k == 1 else many}"
