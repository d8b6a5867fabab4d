"""Fast replay skips the reads a driver says would change nothing: nothing else changes."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from drivers.base import Reading
from drivers.capture.format import read_capture
from shoveld.daemon.config import DeviceConfig, device_signals
from shoveld.replay.sync import SyncReplay

CAPTURE = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures" / "daemon-e2e"


def _devices() -> dict[str, DeviceConfig]:
    out = {}
    for name, dev in read_capture(CAPTURE).devices.items():
        d = dict(dev.settings.get("config") or {})
        d["kind"] = dev.kind
        out[name] = DeviceConfig(name, dev.kind, d, 0.5, device_signals(dev.kind, d))
    return out


def _play(skip: bool, until_s: float, gap: tuple[float, float] | None = None
          ) -> tuple[dict[str, list[tuple[Any, ...]]], dict[str, Any], int]:
    sync = SyncReplay(CAPTURE, _devices())
    if gap is not None:  # the laser falls silent for a while
        tr = sync.transports["laser"]
        keep = [c for c in tr.stream if not gap[0] <= c[0] < gap[1]]
        tr.stream[:] = keep
        tr._times[:] = [c[0] for c in keep]
        tr._chunks[:] = [c[1] for c in keep]
    got: dict[str, list[tuple[Any, ...]]] = {n: [] for n in sync.drivers}

    def sink(name: str) -> Any:
        def put(r: Reading) -> None:
            got[name].append((r.t_host, sorted(r.values.items()), sorted(r.invalid)))
        return put
    sync.attach({n: sink(n) for n in sync.drivers})
    if not skip:
        for d in sync._devs:
            d.idle = None
    k = 0
    while k * 0.01 <= until_s:
        sync.step(k * 0.01)
        k += 1
    health = {n: d.health.as_dict() for n, d in sync.drivers.items()}
    skipped = sum(d.skipped for d in sync._devs)
    sync.close()
    return got, health, skipped


def test_skipping_idle_reads_gives_the_same_readings_and_health() -> None:
    a, ha, skipped = _play(skip=True, until_s=20.0)
    b, hb, none = _play(skip=False, until_s=20.0)
    assert skipped > 500 and none == 0  # the 50 Hz laser is idle on every other tick
    assert a == b
    assert ha == hb


def test_a_silent_laser_is_still_detected_at_the_same_tick() -> None:
    a, ha, _ = _play(skip=True, until_s=12.0, gap=(5.0, 8.0))
    b, hb, _ = _play(skip=False, until_s=12.0, gap=(5.0, 8.0))
    assert ha["laser"]["timeouts"] >= 1
    assert ha["laser"]["reconnects"] >= 1
    assert a == b
    assert ha == hb
