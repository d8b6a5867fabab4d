"""The stepping loop the drivers' span tests share: a recording played tick by tick
through the driver, or with span reads wherever the span reader can start one, so that
the two paths' readings and health can be compared tick for tick."""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any, Protocol

from shoveld.replay.sync import StepClock, SyncDevice


class SpanReader(Protocol):
    def read(self, start: int, stop: int) -> Any: ...


def play(dev: SyncDevice, reader: SpanReader | None, clock: StepClock, ticks: int,
         window: int | None, period: float, span_rows: Callable[[Any], None],
         at: list[int] | None = None) -> list[dict[str, Any]]:
    """Step ``ticks`` ticks of ``period``; where ``reader`` and ``window`` are given, a
    span read of up to ``window`` ticks wherever one can start (its readings go to
    ``span_rows``; the per-tick ones to the device's sink, which may look at ``at[0]``
    for the tick). Returns the driver's health after every tick, and asserts that span
    reads happened when asked for (a test of the span path that never took it would
    pass on the per-tick path alone)."""
    health: list[dict[str, Any]] = []
    k = spans = 0
    while k < ticks:
        got = reader.read(k, min(ticks, k + window)) if reader and window else None
        if got is not None:
            spans += 1
            span_rows(got)
            health += [copy.deepcopy(got.health_after(i).as_dict()) for i in range(got.ticks)]
            k += got.ticks
            continue
        clock.t = k * period
        if at is not None:
            at[0] = k
        dev.step(clock.t)
        health.append(copy.deepcopy(dev.driver.health.as_dict()))
        k += 1
    assert window is None or spans > 0
    return health
