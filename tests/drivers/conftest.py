"""Helpers shared by the driver tests."""

from __future__ import annotations

import time
from collections.abc import Callable

from drivers.base import Driver, Reading


def collect(drv: Driver, seconds: float) -> list[Reading]:
    """Everything the driver reads in ``seconds`` of real time."""
    out: list[Reading] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        drv.read(out.append)
    return out


def wait_for(cond: Callable[[], bool], timeout: float = 5.0) -> None:
    """Poll ``cond`` until it holds; AssertionError after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("condition not reached in time")
        time.sleep(0.01)
