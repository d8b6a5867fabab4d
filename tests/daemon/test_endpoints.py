"""A malformed Zenoh endpoint is refused with one line, in a config and on the command
line (Zenoh would ignore a bad listen endpoint, or fail naming a Rust source file)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from shoveld.daemon.config import ConfigError, parse_config
from shoveld.endpoints import endpoint_error

from .conftest import CAPTURE, PARAMS


@pytest.mark.parametrize("ep", ["tcp/127.0.0.1:7447", "tls/[::1]:7447", "tcp/router.site:7447",
                                "udp/10.0.0.5:7447", "unixsock-stream//run/shoveld.sock",
                                "tcp/127.0.0.1:0"])
def test_good_endpoints(ep: str) -> None:
    assert endpoint_error(ep) is None


@pytest.mark.parametrize("ep,why", [("tcp127.0.0.1:7447", "PROTO/ADDRESS"),
                                    ("tcp/127.0.0.1", "HOST:PORT"),
                                    ("tcp/127.0.0.1:99999", "port"),
                                    ("tcp/127.0.0.1:x", "port"),
                                    ("http/127.0.0.1:80", "unknown protocol"),
                                    ("tcp/[::1:7447", "brackets")])
def test_bad_endpoints_in_a_config_name_the_key(ep: str, why: str) -> None:
    assert why in (endpoint_error(ep) or "")
    with pytest.raises(ConfigError, match=r"zenoh\.listen") as e:
        parse_config({"shovel": {"id": "x", "params": str(PARAMS)},
                      "zenoh": {"listen": [ep]}}, "<test>", require_devices=False)
    assert why in str(e.value)


def test_replay_refuses_a_malformed_listen_endpoint(tmp_path: Path) -> None:
    r = subprocess.run([sys.executable, "-m", "shoveld", "replay", str(CAPTURE), "--fast",
                        "--state-dir", str(tmp_path), "--listen", "tcp/127.0.0.1"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert "--listen" in r.stderr and "HOST:PORT" in r.stderr and "Traceback" not in r.stderr


def test_a_config_that_is_not_text_is_one_line(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from shoveld.cli import main

    cfg = tmp_path / "shoveld.toml"
    cfg.write_bytes(b"[shovel]\nid = \"\xff\xfe\"\n")
    assert main(["check-config", str(cfg)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "shoveld.toml" in err and "not a text file" in err
