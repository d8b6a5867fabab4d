"""One engine, two feeders: the bulk replay gives what the stepped replay gives.

The stepped fast replay runs the drivers, the store and the assembler inside each tick
as the live daemon does; the bulk front end decodes each device alone and builds the
samples with numpy. On every committed capture both must hand the engine the same
samples (bit for bit) and so commit the same passes and trucks, and publish the same
health (apart from what host timing decides: Zenoh's session, the pass-log queue).
"""

from __future__ import annotations

import json
import math
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hil_fixtures.regress import captures
from shoveld.daemon.config import parse_config
from shoveld.installation import Installation, unwrap_deg
from shoveld.model.params import load_params
from shoveld.replay.bulk import BulkAssembler, unwrapped_swing
from shoveld.replay.service import fast_replay_service
from shoveld.sample import CROWD_TARGET_CHANGED, Sample

HOST_TIMED = ("zenoh", "pass_log", "ok")
"""Health fields that depend on host timing (threads, sockets), not on the replay."""


def _row(s: Sample) -> tuple[Any, ...]:
    return (*("nan" if math.isnan(x) else x for x in s.as_row()), tuple(sorted(s.invalid)))


def _health(msg: dict[str, Any]) -> dict[str, Any]:
    out = {k: v for k, v in msg.items() if k not in HOST_TIMED}
    out["problems"] = [p for p in msg["problems"] if not p.startswith("zenoh")]
    out["loop"] = {k: v for k, v in msg["loop"].items()
                   if k not in ("actual_rate_hz", "tick_work_ms")}
    return out


def _silence(transport: Any, start: float, end: float) -> None:
    """Drop a serial device's recorded data in [start, end): the device falls silent."""
    keep = [c for c in transport.stream if not start <= c[0] < end]
    transport.stream[:] = keep
    transport._times[:] = [c[0] for c in keep]
    transport._chunks[:] = [c[1] for c in keep]


def _replay(capture: Path, tmp: Path, bulk: bool, until_s: float | None = None,
            span_ticks: int | None = None,
            gaps: dict[str, tuple[float, float]] | None = None) -> dict[str, Any]:
    """Samples, health messages, passes and trucks of a fast replay of ``capture``
    (``span_ticks``: the bulk feed's span; ``gaps``: serial devices silent then)."""
    exp = json.loads((capture / "expected.json").read_text())
    params = capture / "params.toml"
    cfg = parse_config({"shovel": {"id": "bulk", "params": str(params),
                                   "state_dir": str(tmp / ("bulk" if bulk else "stepped"))},
                        "zenoh": {"listen": []},
                        "truck": {"target_kg": float(exp["truck_target_kg"])}},
                       "<test>", require_devices=False)
    rr = fast_replay_service(capture, cfg, load_params(params), bulk=bulk)
    svc = rr.service
    sync = rr.session.sync if bulk else rr.session
    for device, gap in (gaps or {}).items():
        _silence(sync.transports[device], *gap)
    if span_ticks is not None:
        assert isinstance(svc.assembler, BulkAssembler)  # a span is the bulk feed's
        svc.assembler.feed.span_ticks = span_ticks
    got: dict[str, Any] = {"samples": [], "health": [], "pass": [], "truck": []}
    sample = svc.assembler.sample
    svc.assembler.sample = (  # type: ignore[method-assign]  # each sample is kept
        lambda t: got["samples"].append(sample(t)) or got["samples"][-1])
    publish_health = svc._publish_health

    def health(t: float) -> None:
        publish_health(t)
        got["health"].append(_health(json.loads(json.dumps(svc.health_msg))))  # as sent
    svc._publish_health = health  # type: ignore[method-assign]
    svc.on_event = lambda kind, msg: got[kind].append(msg)
    try:
        svc.start()
        got["figures"] = rr.run(threading.Event(), until_s=until_s)
        svc.flush()
    finally:
        rr.close()
    return got


@pytest.mark.parametrize("capture", captures(), ids=lambda p: p.name)
def test_bulk_and_stepped_replay_feed_the_engine_alike(capture: Path, tmp_path: Path) -> None:
    stepped = _replay(capture, tmp_path, bulk=False)
    bulk = _replay(capture, tmp_path, bulk=True)
    assert len(bulk["samples"]) == len(stepped["samples"]) == stepped["figures"]["ticks"]
    assert [_row(s) for s in bulk["samples"]] == [_row(s) for s in stepped["samples"]]
    assert stepped["pass"] and bulk["pass"] == stepped["pass"]
    assert bulk["truck"] == stepped["truck"]
    assert bulk["health"] == stepped["health"]
    assert bulk["figures"]["capture_s"] == stepped["figures"]["capture_s"]


def test_bulk_replay_stops_where_asked(tmp_path: Path) -> None:
    capture = captures()[0]
    stepped = _replay(capture, tmp_path, bulk=False, until_s=12.345)
    bulk = _replay(capture, tmp_path, bulk=True, until_s=12.345)
    assert bulk["figures"]["capture_s"] == stepped["figures"]["capture_s"] >= 12.345
    assert [_row(s) for s in bulk["samples"]] == [_row(s) for s in stepped["samples"]]


def test_span_boundaries_change_nothing(tmp_path: Path) -> None:
    """Short spans: the newest reading, the unwrapped swing, the invalid lists and the
    reading counts carry over from span to span."""
    capture = captures()[0]
    stepped = _replay(capture, tmp_path, bulk=False, until_s=40.0)
    bulk = _replay(capture, tmp_path, bulk=True, until_s=40.0, span_ticks=333)
    assert [_row(s) for s in bulk["samples"]] == [_row(s) for s in stepped["samples"]]
    assert bulk["health"] == stepped["health"]


def test_a_silent_laser_is_stale_then_disconnected_alike(tmp_path: Path) -> None:
    """The laser stops for 6 s: stale, then its driver's silence timeout disconnects it
    and the reconnects back off in capture time; samples and health agree tick by tick."""
    capture = next(p for p in captures() if p.name == "daemon-e2e")
    gap = (20.0, 26.0)
    stepped = _replay(capture, tmp_path, bulk=False, until_s=35.0, gaps={"laser": gap})
    bulk = _replay(capture, tmp_path, bulk=True, until_s=35.0, gaps={"laser": gap},
                   span_ticks=1000)
    states = {h["drivers"]["laser"]["state"] for h in stepped["health"]}
    assert {"stale", "disconnected"} <= states  # the gap is seen as both
    assert stepped["health"][-1]["drivers"]["laser"]["reconnects"] >= 1
    assert [_row(s) for s in bulk["samples"]] == [_row(s) for s in stepped["samples"]]
    assert bulk["health"] == stepped["health"]


def test_a_silent_mti_times_out_in_capture_time_alike(tmp_path: Path) -> None:
    """The MTi stops for 3 s: its driver's 1 s data timeout runs on capture time in fast
    replay (host time would depend on how fast the machine replays, and on how far
    apart the bulk feed steps the driver), so both feeders reconnect it at the same
    tick, through the handshake answered from the recording."""
    capture = next(p for p in captures() if p.name == "daemon-e2e")
    gap = (30.0, 33.0)
    stepped = _replay(capture, tmp_path, bulk=False, until_s=40.0, gaps={"mti": gap})
    bulk = _replay(capture, tmp_path, bulk=True, until_s=40.0, gaps={"mti": gap},
                   span_ticks=777)
    mti = stepped["health"][-1]["drivers"]["mti"]
    assert mti["timeouts"] >= 1 and mti["reconnects"] >= 1 and mti["connected"]
    assert [_row(s) for s in bulk["samples"]] == [_row(s) for s in stepped["samples"]]
    assert bulk["health"] == stepped["health"]


def test_a_laser_that_changes_target_is_marked_alike(tmp_path: Path) -> None:
    """Something stays in the laser's beam for 2 s in each pass, taken as the target
    after 0.5 s, and left for the handle 0.5 s after it goes: both feeders mark the same
    ticks (the count of targets taken, carried by the readings, grows there; short
    spans, so a mark can fall on a span's edge), and no pass is weighed."""
    import random
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
    import laser_strays

    base = laser_strays.replay(laser_strays.CAPTURE)
    blocks = laser_strays.pass_blocks(base["spans"], 2.0, random.Random(7))
    capture = laser_strays.stray_capture(tmp_path / "c", 0.0, 7, True, blocks,
                                         {"other_target_s": 0.5})
    stepped = _replay(capture, tmp_path, bulk=False)
    bulk = _replay(capture, tmp_path, bulk=True, span_ticks=250)
    marked = [i for i, s in enumerate(stepped["samples"]) if CROWD_TARGET_CHANGED in s.invalid]
    assert len(marked) == 2 * len(blocks)  # onto it, and back to the handle
    assert [_row(s) for s in bulk["samples"]] == [_row(s) for s in stepped["samples"]]
    assert len(stepped["pass"]) == 3 and bulk["pass"] == stepped["pass"]
    assert not any(p["valid"] for p in stepped["pass"])
    assert all("laser changed target" in p["reason"] for p in stepped["pass"])
    assert bulk["health"] == stepped["health"]


def test_the_swing_is_unwrapped_as_the_assembler_does() -> None:
    """Through the +-180 wrap both ways, in big and small steps, from a NaN start."""
    rng = np.random.default_rng(3)
    yaw = np.remainder(np.cumsum(rng.normal(0, 40, 5000)) + 180.0, 360.0) - 180.0
    yaw[::17] = rng.uniform(-180, 180, len(yaw[::17]))
    for inst in (Installation(), Installation(swing_yaw_zero_deg=137.25, swing_yaw_sign=-1.0)):
        prev, want = math.nan, []
        for y in yaw.tolist():
            prev = unwrap_deg(prev, inst.swing_deg(y))
            want.append(prev)
        got, last = unwrapped_swing(inst, yaw, math.nan)
        assert got == want and last == want[-1]
