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

import pytest

from hil_fixtures.regress import captures
from shoveld.daemon.config import parse_config
from shoveld.daemon.replay import fast_replay_service
from shoveld.model.params import load_params
from shoveld.sample import Sample

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


def _replay(capture: Path, tmp: Path, bulk: bool, until_s: float | None = None
            ) -> dict[str, Any]:
    """Samples, health messages, passes and trucks of a fast replay of ``capture``."""
    exp = json.loads((capture / "expected.json").read_text())
    params = capture / "params.toml"
    cfg = parse_config({"shovel": {"id": "bulk", "params": str(params),
                                   "state_dir": str(tmp / ("bulk" if bulk else "stepped"))},
                        "zenoh": {"listen": []},
                        "truck": {"target_kg": float(exp["truck_target_kg"])}},
                       "<test>", require_devices=False)
    rr = fast_replay_service(capture, cfg, load_params(params), bulk=bulk)
    svc = rr.service
    got: dict[str, Any] = {"samples": [], "health": [], "pass": [], "truck": []}
    sample = svc.assembler.sample
    svc.assembler.sample = lambda t: got["samples"].append(sample(t)) or got["samples"][-1]
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
