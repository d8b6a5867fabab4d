"""``shoveld run`` as systemd runs it: READY once the drivers are up, watchdog pings from
a healthy loop, journal levels on stderr, clean stop on SIGTERM."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from hil_fixtures.virtual_shovel import VirtualShovel
from shoveld.cli.demo import write_demo_config
from shoveld.daemon.notify import Notifier
from shoveld.daemon.service import Service
from shoveld.engine.loop import Event
from shoveld.model.params import ModelParams
from shoveld.replay.table import table_service
from shoveld.sample import Sample
from shoveld.signals.table import SignalsTable

from .conftest import PARAMS, free_port, make_cfg


def recv_until(sock: socket.socket, want: bytes, timeout: float) -> list[bytes]:
    got: list[bytes] = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        sock.settimeout(max(0.01, end - time.monotonic()))
        try:
            msg = sock.recv(4096)
        except TimeoutError:
            break
        got.append(msg)
        if msg.startswith(want):
            return got
    raise AssertionError(f"no {want!r} within {timeout} s; got {got}")


def test_run_under_systemd_protocol(tmp_path: Path, e2e_table: SignalsTable) -> None:
    notify = tmp_path / "notify"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(notify))
    with VirtualShovel(e2e_table) as vs:
        cfg = write_demo_config(tmp_path / "shoveld.toml", params=PARAMS,
                                state_dir=tmp_path / "state", port=free_port(),
                                truck_target=62000.0, shovel_config=vs.config())
        env = {**os.environ, "NOTIFY_SOCKET": str(notify), "WATCHDOG_USEC": "400000",
               "JOURNAL_STREAM": "8:1234"}
        env.pop("WATCHDOG_PID", None)
        proc = subprocess.Popen([sys.executable, "-m", "shoveld", "-v", "run", "--config",
                                 str(cfg)], env=env, stderr=subprocess.PIPE, text=True)
        try:
            got = recv_until(sock, b"READY=1", 20.0)
            assert got[-1] == b"READY=1\nSTATUS=running"  # all drivers up, not degraded
            pings = 0
            t0 = time.monotonic()
            while pings < 4 and time.monotonic() - t0 < 3.0:
                sock.settimeout(1.0)
                pings += sock.recv(100) == b"WATCHDOG=1"
            assert pings >= 4
            proc.send_signal(signal.SIGTERM)
            recv_until(sock, b"STOPPING=1", 10.0)
            _, err = proc.communicate(timeout=15)
        finally:
            if proc.poll() is None:
                proc.kill()
            sock.close()
    assert proc.returncode == 0, err
    lines = err.splitlines()
    assert any(line.startswith("<6>INFO shoveld.run: shoveld demo starting") for line in lines)
    assert any(line.startswith("<6>INFO shoveld.run: stopped") for line in lines)


def test_watchdog_only_while_healthy(tmp_path: Path, e2e_table: SignalsTable,
                                     params: ModelParams) -> None:
    path = tmp_path / "n"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(0.2)
    notifier = Notifier({"NOTIFY_SOCKET": str(path), "WATCHDOG_USEC": "2"})
    svc, feed = table_service(e2e_table, make_cfg(tmp_path), params, notifier=notifier)
    svc.start()
    try:
        svc.loop.behind_s = 5.0  # the loop is far behind its schedule
        svc._tick(0.0)
        msgs = []
        try:
            while True:
                msgs.append(sock.recv(100))
        except TimeoutError:
            pass
        assert b"WATCHDOG=1" not in msgs
        svc.loop.behind_s = 0.0
        svc._tick(0.01)
        assert sock.recv(100) == b"WATCHDOG=1"
    finally:
        svc.close()
        sock.close()


def test_a_failing_tick_is_counted_and_persistent_failure_starves_the_watchdog(
        tmp_path: Path, e2e_table: SignalsTable, params: ModelParams) -> None:
    path = tmp_path / "n"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(0.2)
    notifier = Notifier({"NOTIFY_SOCKET": str(path), "WATCHDOG_USEC": "2"})
    svc, feed = table_service(e2e_table, make_cfg(tmp_path), params, notifier=notifier)
    svc.start()
    engine = svc.engine
    assert engine is not None
    real_step = engine.step
    fail = {"n": 1}

    def flaky(s: Sample) -> list[Event]:
        if fail["n"] > 0:
            fail["n"] -= 1
            raise ValueError("strange reading")
        return real_step(s)
    engine.step = flaky  # type: ignore[method-assign]  # the engine's step fails on cue
    try:
        svc.run(threading.Event(), max_ticks=20)
        assert svc.tick_errors == 1 and svc.loop_stats.ticks == 20
        assert svc._healthy()
        fail["n"] = 10_000
        svc.run(threading.Event(), max_ticks=Service.MAX_CONSECUTIVE_ERRORS + 5)
        assert not svc._healthy()
        while True:  # drain what was sent while healthy
            try:
                sock.recv(100)
            except TimeoutError:
                break
        svc._safe_tick(1000.0)
        with pytest.raises(TimeoutError):
            while sock.recv(100) != b"WATCHDOG=1":
                pass
    finally:
        svc.close()
        sock.close()
