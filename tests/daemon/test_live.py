"""Live: the real drivers on the virtual shovel, faults injected, the loop keeps its rate."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from hil_fixtures.virtual_shovel import VirtualShovel
from shoveld.daemon.config import parse_config
from shoveld.daemon.service import Service
from shoveld.model.params import ModelParams
from shoveld.signals.table import SignalsTable

from .conftest import PARAMS, free_port, wait_for

PEER = """
import sys, time, zenoh, json
c = zenoh.Config()
c.insert_json5("mode", '"peer"')
c.insert_json5("connect/endpoints", json.dumps([sys.argv[1]]))
c.insert_json5("scouting/multicast/enabled", "false")
s = zenoh.open(c)
sub = s.declare_subscriber("shovel/**", lambda x: None)
print("up", flush=True)
time.sleep(60)
"""


def problems_of(svc: Service) -> list[str]:
    return list((svc.health_msg or {}).get("problems") or [])


def test_faults_are_reported_and_the_loop_keeps_its_rate(
        tmp_path: Path, e2e_table: SignalsTable, params: ModelParams) -> None:
    port = free_port()
    with VirtualShovel(e2e_table) as vs:
        vc = vs.config()
        cfg = parse_config({"shovel": {"id": "live", "params": str(PARAMS),
                                       "state_dir": str(tmp_path)},
                            "loop": {"health_period_s": 0.25},
                            "zenoh": {"listen": [f"tcp/127.0.0.1:{port}"]},
                            "installation": vc["installation"], "devices": vc["devices"]})
        svc = Service(cfg, params)
        svc.start(zenoh_wait_s=5.0)
        stop = threading.Event()
        loop = threading.Thread(target=svc.run, args=(stop,))
        peer = subprocess.Popen([sys.executable, "-c", PEER, f"tcp/127.0.0.1:{port}"],
                                stdout=subprocess.PIPE, text=True)
        seen: dict[str, list[str]] = {}
        try:
            loop.start()
            assert svc.wait_drivers(10.0), {n: d.health.last_error
                                            for n, d in svc.drivers.items()}
            assert peer.stdout is not None and peer.stdout.readline().strip() == "up"
            assert wait_for(lambda: bool(svc.health_msg and svc.health_msg["ok"]), 5.0), \
                problems_of(svc)
            # health is refreshed every period: the new peer shows in the next one
            assert wait_for(lambda: svc.health_msg is not None
                            and svc.health_msg["zenoh"]["peers"] >= 1, 5.0), svc.health_msg
            t_start, ticks0 = time.monotonic(), svc.loop_stats.ticks
            # a Zenoh peer that disappears without a goodbye
            os.kill(peer.pid, signal.SIGKILL)
            # a babbling laser
            assert vs.laser is not None
            vs.laser.babble = 1.0
            assert wait_for(lambda: any("laser" in p for p in problems_of(svc)), 5.0)
            seen["laser"] = problems_of(svc)
            # its last good reading turns stale once older than max_age_s
            assert wait_for(lambda: svc.assembler.state["laser"].state in
                            ("stale", "disconnected", "invalid"), 5.0), \
                svc.assembler.state["laser"]
            # a Modbus module that stops answering
            vs.adc_motors.silent = True
            assert wait_for(lambda: any(p.startswith("adc_motors") for p in problems_of(svc)),
                            5.0)
            seen["adc"] = problems_of(svc)
            # an MTi that goes quiet
            vs.mti.go_silent()
            assert wait_for(lambda: any(p.startswith("mti") for p in problems_of(svc)), 5.0)
            seen["mti"] = problems_of(svc)
            live = svc.live_msg
            elapsed = time.monotonic() - t_start
            ticks = svc.loop_stats.ticks - ticks0
        finally:
            stop.set()
            loop.join(10)
            peer.kill()
            peer.wait()
            svc.close()
    text = " | ".join(p for ps in seen.values() for p in ps)
    assert "babbling" in text or "laser: no reading" in text or "laser: disconnected" in text
    assert "adc_motors" in text
    assert live is not None and live["valid"] is False and live["payload_kg"] is None
    # the loop kept its rate through all of it
    assert abs(ticks - 100.0 * elapsed) <= max(3.0, 0.02 * 100.0 * elapsed), (ticks, elapsed)
    assert svc.loop_stats.overruns <= 0.01 * svc.loop_stats.ticks
