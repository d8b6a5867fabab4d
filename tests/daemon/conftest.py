"""Shared fixtures of the daemon tests: params, a small table, free ports, Zenoh helpers."""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from shoveld.daemon.config import DaemonConfig, parse_config
from shoveld.model.params import ModelParams, load_params
from shoveld.signals.table import SignalsTable

ROOT = Path(__file__).resolve().parents[2]
CAPTURE = ROOT / "hil_fixtures" / "captures" / "daemon-e2e"
PARAMS = CAPTURE / "params.toml"


def free_port() -> int:
    """A free TCP port on 127.0.0.1 (never 7447, which the demo uses)."""
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        if port != 7447:
            return port


@pytest.fixture(scope="session")
def params() -> ModelParams:
    return load_params(PARAMS)


@pytest.fixture(scope="session")
def e2e_table() -> SignalsTable:
    """The table the committed capture was recorded from (3 passes, 2 trucks of 62 t)."""
    from shoveld.sim.scenario import simulate_cycles

    return simulate_cycles(3, seed=11, truck_target_kg=62000.0,
                           payloads=[31000.0, 29500.0, 33000.0]).table


def make_cfg(tmp_path: Path, port: int | None = None, **sections: Any) -> DaemonConfig:
    """A daemon config without devices, Zenoh peer on a free loopback port."""
    doc: dict[str, Any] = {
        "shovel": {"id": "t1", "params": str(PARAMS), "state_dir": str(tmp_path / "state")},
        "zenoh": {"listen": [f"tcp/127.0.0.1:{port or free_port()}"]},
        "truck": {"target_kg": 62000.0},
    }
    for k, v in sections.items():
        doc[k] = {**doc.get(k, {}), **v}
    return parse_config(doc, "<test>", require_devices=False)


def wait_for(pred: Callable[[], bool], timeout: float, poll_s: float = 0.05) -> bool:
    """Poll ``pred`` until it holds or ``timeout`` passes; its last value."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(poll_s)
    return pred()


class Collector:
    """A Zenoh client session collecting JSON samples under a key expression."""

    def __init__(self, endpoint: str, key: str = "shovel/**", mode: str = "client") -> None:
        import zenoh

        from shoveld.daemon.publisher import zenoh_config

        self.session = zenoh.open(zenoh_config(mode, (), [endpoint]))
        self.samples: list[tuple[str, dict[str, Any], str]] = []
        self.lock = threading.Lock()

        def on(sample: Any) -> None:
            with self.lock:
                self.samples.append((str(sample.key_expr), json.loads(
                    sample.payload.to_bytes()), str(sample.encoding)))
        self.sub = self.session.declare_subscriber(key, on)

    def of(self, suffix: str) -> list[dict[str, Any]]:
        with self.lock:
            return [m for k, m, _ in self.samples if k.endswith("/" + suffix)]

    def wait(self, pred: Callable[[], bool], timeout: float = 10.0) -> bool:
        return wait_for(pred, timeout, poll_s=0.02)

    def close(self) -> None:
        self.sub.undeclare()
        self.session.close()


@pytest.fixture
def collector_factory() -> Iterator[Callable[..., Collector]]:
    made: list[Collector] = []

    def make(endpoint: str, key: str = "shovel/**", mode: str = "client") -> Collector:
        c = Collector(endpoint, key, mode)
        made.append(c)
        return c
    yield make
    for c in made:
        c.close()
