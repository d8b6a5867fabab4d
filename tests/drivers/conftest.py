"""Helpers shared by the driver tests."""

from __future__ import annotations

import time
from collections.abc import Callable

from drivers.base import Driver, Reading
from drivers.capture.format import RegisterRead


def collect(drv: Driver, seconds: float) -> list[Reading]:
    """Everything the driver reads in ``seconds`` of real time."""
    out: list[Reading] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        drv.read(out.append)
    return out


def t_device(r: Reading) -> float:
    """The device's own time of a reading from a driver that stamps every reading."""
    assert r.t_device is not None, r
    return r.t_device


def answered(r: RegisterRead) -> tuple[int, ...]:
    """The words of a recorded read that answered."""
    assert r.registers is not None, r
    return r.registers


def wait_for(cond: Callable[[], bool], timeout: float = 5.0) -> None:
    """Poll ``cond`` until it holds; AssertionError after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("condition not reached in time")
        time.sleep(0.01)
