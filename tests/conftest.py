"""What every test shares: the root logger left as the test found it."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True)
def _root_logger_restored() -> Iterator[None]:
    """A command run in this process (``main([...])``) sets up the daemon's logging: a
    handler on the stderr pytest captured for that test. Left on the root logger, it
    made every later test's log lines go to a closed file, and a failing test's output
    carry a "--- Logging error ---" traceback of another test's making."""
    root = logging.getLogger()
    before, level = set(root.handlers), root.level
    yield
    for h in list(root.handlers):
        if type(h) is logging.StreamHandler and h not in before:  # pytest's are subclasses
            root.removeHandler(h)
    root.setLevel(level)
