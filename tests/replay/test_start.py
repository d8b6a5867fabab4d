"""The fast replay's start: the Zenoh session opens while the capture is read, once,
and is closed again when the capture cannot be read."""

from __future__ import annotations

import socket
import threading
from pathlib import Path

import pytest

from drivers.capture.format import CaptureFormatError
from shoveld.daemon.publisher import Publisher
from shoveld.model.params import load_params
from shoveld.replay.service import fast_replay_service
from tests.daemon.conftest import CAPTURE, PARAMS, free_port, make_cfg, wait_for


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def test_the_session_opens_while_the_capture_is_read_and_only_once(tmp_path: Path) -> None:
    port = free_port()
    cfg = make_cfg(tmp_path, port)
    rr = fast_replay_service(CAPTURE, cfg, load_params(PARAMS))
    try:
        pub = rr.service.publisher
        first = pub._thread
        assert first is not None  # opening before the service starts
        assert wait_for(pub.opened.is_set, 10.0)
        assert not _port_free(port)  # listening already
        rr.service.start(zenoh_wait_s=5.0)
        assert pub._thread is first  # start waited, and opened no second session
        assert [t for t in threading.enumerate() if t.name == "zenoh-open"] in ([], [first])
        figures = rr.run(threading.Event(), until_s=5.0)
        assert figures["capture_s"] >= 5.0
    finally:
        rr.close()
    assert wait_for(lambda: _port_free(port), 10.0)


def test_a_capture_that_cannot_be_read_closes_the_session_it_opened(tmp_path: Path) -> None:
    port = free_port()
    bad = tmp_path / "capture"
    bad.mkdir()
    (bad / "manifest.json").write_text('{"format": "something else"}')
    with pytest.raises(CaptureFormatError):
        fast_replay_service(bad, make_cfg(tmp_path, port), load_params(PARAMS))
    # the opening thread ends once the session is open (or given up): then nothing listens
    assert wait_for(lambda: not any(t.name == "zenoh-open" for t in threading.enumerate()),
                    10.0)
    assert wait_for(lambda: _port_free(port), 5.0)


def test_starting_a_started_publisher_only_waits(tmp_path: Path) -> None:
    cfg = make_cfg(tmp_path)
    pub = Publisher(cfg.zenoh, "t1").start()
    try:
        first = pub._thread
        assert pub.start(wait_s=10.0) is pub and pub._thread is first
        assert pub.opened.is_set()
    finally:
        pub.close()
