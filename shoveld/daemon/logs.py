"""Logging for the service: levels the journal understands, plain lines in a terminal.

Under systemd (``$JOURNAL_STREAM`` set) each line starts with the syslog priority
``<N>``, which journald turns into the entry's level (``SyslogLevelPrefix=`` is on by
default), so ``journalctl -p warning -u shoveld`` works with stdout/stderr logging.
"""

from __future__ import annotations

import logging
import os
import sys

_PRIORITY = {logging.DEBUG: 7, logging.INFO: 6, logging.WARNING: 4, logging.ERROR: 3,
             logging.CRITICAL: 2}


class JournalFormatter(logging.Formatter):
    """``<priority>LEVEL name: message``; multi-line messages keep the prefix per line."""

    def format(self, record: logging.LogRecord) -> str:
        prio = _PRIORITY.get(record.levelno, 6)
        text = super().format(record)
        return "\n".join(f"<{prio}>{line}" for line in text.splitlines() or [""])


def setup_logging(level: str | int, journal: bool | None = None) -> None:
    """Configure the root logger once for the daemon (stderr, journal-aware)."""
    if journal is None:
        journal = bool(os.environ.get("JOURNAL_STREAM"))
    root = logging.getLogger()
    for h in list(root.handlers):
        root.removeHandler(h)
    handler = logging.StreamHandler(sys.stderr)
    fmt = "%(levelname)s %(name)s: %(message)s"
    if journal:
        handler.setFormatter(JournalFormatter(fmt))
    else:
        handler.setFormatter(logging.Formatter("%(asctime)s " + fmt))
    root.addHandler(handler)
    root.setLevel(level if isinstance(level, int) else level.upper())
