"""The health message: what each driver, the loop, Zenoh and the pass log are doing.

Published on ``<prefix>/<id>/health`` every ``loop.health_period_s`` and part of the
status query. It exists so that a sensor that stops or babbles, a Modbus module
that times out or a network that is gone is *said* (``problems`` lists them in
words) instead of showing up as a wrong number somewhere else.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from drivers.base import Driver
from shoveld.daemon.assemble import DeviceState
from shoveld.daemon.loop import percentiles
from shoveld.daemon.store import ReadingStore
from shoveld.payload.misfit import (
    MISFIT_PERSISTENT,
    PASSES_TO_TRIALS_WARN,
    passes_to_trials_note,
)
from shoveld.words import n_of


class LatencyStats:
    """Ring of arrival-to-publish latencies (seconds)."""

    def __init__(self, window: int = 4000, keep_all: bool = False) -> None:
        self._window = window
        self._v = [0.0] * window
        self._i = 0
        self._n = 0
        self.keep_all = keep_all
        self.all: list[float] = []

    def add(self, x: float) -> None:
        i = self._i
        self._v[i] = x
        self._i = 0 if i + 1 == self._window else i + 1
        self._n += 1
        if self.keep_all:
            self.all.append(x)

    def as_dict(self) -> dict[str, Any] | None:
        n = min(self._n, self._window)
        if not n:
            return None
        (p50, p99), vmax = percentiles(self._v[:n])
        return {"p50": round(1e3 * p50, 3), "p99": round(1e3 * p99, 3),
                "max": round(1e3 * vmax, 3), "n": self._n}


class RateMeter:
    """Readings per second of each device over the last health period (clock time)."""

    def __init__(self) -> None:
        self._prev: dict[str, tuple[float, int]] = {}

    def rate(self, device: str, t: float, count: int) -> float | None:
        prev = self._prev.get(device)
        self._prev[device] = (t, count)
        if prev is None or t <= prev[0]:
            return None
        return round((count - prev[1]) / (t - prev[0]), 2)


def driver_health(name: str, driver: Driver | None, state: DeviceState, store: ReadingStore,
                  rates: RateMeter, t: float) -> dict[str, Any]:
    d: dict[str, Any] = {"state": state.state,
                         "age_s": None if state.age_s is None else round(state.age_s, 4),
                         "rate_hz": rates.rate(name, t, store.count(name)),
                         "readings": store.count(name)}
    if state.invalid:
        d["invalid_signals"] = list(state.invalid)
    if driver is not None:
        h = driver.health
        d.update({"connected": h.connected, "messages": h.messages,
                  "bad_frames": h.bad_frames, "rejected_bytes": h.rejected_bytes,
                  "timeouts": h.timeouts, "reconnects": h.reconnects,
                  "last_error": h.last_error})
        for k, v in h.extra.items():
            d.setdefault(k, v)
    return d


def problems(drivers: Mapping[str, dict[str, Any]], loop: dict[str, Any],
             zenoh: dict[str, Any], persist: dict[str, Any]) -> list[str]:
    """Plain-language list of what is wrong (empty: all well)."""
    out: list[str] = []
    for name, d in drivers.items():
        st = d.get("state")
        if st == "disconnected":
            out.append(f"{name}: disconnected ({d.get('last_error') or 'no connection'})")
        elif st == "no_data":
            out.append(f"{name}: no data yet")
        elif st == "stale":
            out.append(f"{name}: no reading for {d.get('age_s') or 0:.2f} s")
        elif st == "invalid":
            out.append(f"{name}: invalid {', '.join(d.get('invalid_signals', []))}")
        if d.get("babbling"):
            out.append(f"{name}: babbling (malformed data)")
        if d.get("answering_late"):
            out.append(f"{name}: answering after its timeout ({d.get('late_answers')} late "
                       "answers): timeout_s too short for it?")
        if d.get("jumping"):
            out.append(f"{name}: jumping (distances the handle cannot reach: dirty target, "
                       "something in the beam?)")
        chans = d.get("channels")
        if isinstance(chans, dict):
            # "late": answering after the timeout over RTU, said by the line above
            bad = [c for c, h in chans.items() if isinstance(h, dict)
                   and h.get("state") not in ("ok", None, "late")]
            if bad:
                out.append(f"{name}: channels {', '.join(bad)} not answering")
    if not zenoh.get("open"):
        out.append(f"zenoh: session not open ({zenoh.get('last_error') or 'connecting'})")
    elif zenoh.get("unreached_s") is not None:
        # the site's router gone (or its link): nobody through it hears this, a peer
        # beside the shovel does, and the journal has it (publisher._watch_links); the
        # seconds count from the health message that first saw it
        out.append(f"zenoh: cannot reach {', '.join(zenoh.get('connect') or [])} for "
                   f"{zenoh['unreached_s']:.1f} s: passes are kept in the pass log")
    if persist.get("last_error"):
        out.append(f"pass log: {persist['last_error']}")
    if loop.get("failing_now"):
        out.append(f"loop: the last {n_of(loop['failing_now'], 'tick', 'ticks')} failed "
                   "(see the log)")
    fit = loop.get("misfit")
    if isinstance(fit, dict) and (fit.get("recent_above") or 0) >= MISFIT_PERSISTENT:
        # one pass above the level is marked on the cab; most of the last ones above it
        # is the machine or a sensor, for as long as it lasts (docs/engine.md, misfit)
        out.append(f"payload: the model did not fit {fit['recent_above']} of the last "
                   f"{fit.get('recent')} passes (misfit above {fit.get('warn') or 0:g}): it lacks "
                   "something this machine does, or a sensor measures something else; "
                   "shoveld diagnose names it")
    cal = loop.get("calibration")
    if isinstance(cal, dict) and cal.get("above"):
        # the misfit above cannot say it: it is read against this calibration's noise,
        # which took the missing term in (docs/engine.md, "The calibration's own check")
        out.append("payload: " + passes_to_trials_note(cal["above"],
                                                      cal.get("warn", PASSES_TO_TRIALS_WARN)))
    doubt = loop.get("crowd_doubt")
    if isinstance(doubt, dict) and doubt.get("refusing") and doubt.get("doubt"):
        # a gap alone is common (the laser's dust, a reconnect); passes that stop fitting
        # after it are not weighed until one fits again (docs/engine.md, "A crowd in doubt")
        out.append(f"payload: {n_of(doubt['refusing'], 'pass', 'passes')} not weighed since the "
                   f"crowd laser {doubt['doubt']}: the model does not fit them as it fitted "
                   f"this machine (misfit {doubt.get('last') or 0:.0f} against its usual "
                   f"{doubt.get('usual') or 0:.2f}); the laser may see something other than "
                   "the handle: check its beam and target")
    empty = loop.get("empty_dipper")
    if isinstance(empty, dict) and empty.get("beyond") and empty.get("median_kg") is not None:
        # a calibration (or model) fault the passes may share, by less or more than the
        # empty weight: the operator and the office see it as long as it lasts, the log
        # says the causes (docs/engine.md, "The empty dipper on its returns")
        out.append(f"payload: the empty dipper weighs {empty['median_kg'] / 1000:+.1f} t on "
                   f"its returns (median of the last {empty.get('of_last')}): the calibration or "
                   "the model is off, the passes may be too; weigh a known load")
    recent, ticks = loop.get("overruns_recent") or 0, loop.get("ticks_recent") or 0
    if recent and recent > 0.02 * max(ticks, 1):
        out.append(f"loop: {n_of(recent, 'overrun', 'overruns')} in the last "
                   f"{n_of(ticks, 'tick', 'ticks')}")
    return out
