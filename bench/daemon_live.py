"""Daemon live figures at 100 Hz: tick jitter, arrival-to-publish latency, CPU per second.

Two processes, like a shovel: this one runs the daemon exactly as ``shoveld run``
does (``Service`` on the host monotonic clock, one thread per driver, Zenoh peer on
loopback); a child process runs the virtual shovel's emulators (MTi at 100 Hz on a pty,
AR4000 at 50 Hz on a pty, two Modbus TCP modules) and a Zenoh subscriber that timestamps
every ``joints`` message it receives. Figures:

* tick jitter: wake-up lateness against each absolute deadline (p50, p99, max);
* arrival -> publish: from a reading reaching the daemon's store to the put of the
  first message computed from it (includes the wait for the next tick, 0-10 ms);
* tick -> subscriber: from the tick's deadline to the other process receiving the
  message (processing + Zenoh over loopback);
* CPU: this process's CPU seconds per second (drivers, loop, engine, Zenoh).

Usage: ``.venv/bin/python bench/daemon_live.py [--seconds 60] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PARAMS = ROOT / "hil_fixtures" / "captures" / "daemon-e2e" / "params.toml"

CHILD = r"""
import json, sys, time, threading
import numpy as np
import zenoh
from hil_fixtures.virtual_shovel import VirtualShovel
from shoveld.sim.scenario import simulate_cycles
from shoveld.daemon.publisher import zenoh_config
table = simulate_cycles(int(sys.argv[1]), seed=3).table
lat = []
with VirtualShovel(table) as vs:
    print(json.dumps(vs.config()), flush=True)
    endpoint = sys.stdin.readline().strip()
    s = zenoh.open(zenoh_config("client", (), [endpoint]))
    def on(sample):
        now = time.time()
        lat.append(now - json.loads(sample.payload.to_bytes())["time"])
    sub = s.declare_subscriber("shovel/bench/joints", on)
    print("subscribed", flush=True)
    sys.stdin.readline()
    sub.undeclare()
    s.close()
v = np.array(lat[50:]) * 1e3
print(json.dumps({"n": len(v), "p50": float(np.percentile(v, 50)),
                  "p99": float(np.percentile(v, 99)), "max": float(v.max())}), flush=True)
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def pct(v: list[float] | np.ndarray, scale: float = 1e3) -> dict[str, float]:
    a = np.asarray(v) * scale
    return {"p50": round(float(np.percentile(a, 50)), 3), "p99": round(float(np.percentile(a,
                                                                                        99)), 3),
            "max": round(float(a.max()), 3), "n": int(a.size)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--publish-rate", type=float, default=None,
                    help="joints and live payload rate (default: every tick, so the latency "
                         "figure is not stretched by decimation; the service default is 10)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    from shoveld.daemon.config import parse_config
    from shoveld.daemon.service import Service
    from shoveld.model.params import load_params

    passes = max(3, int(args.seconds / 25) + 2)
    pub_rate = args.publish_rate or args.rate
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(passes)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True, env=env)
    assert child.stdin is not None and child.stdout is not None
    vc = json.loads(child.stdout.readline())
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        cfg = parse_config({
            "shovel": {"id": "bench", "params": str(PARAMS), "state_dir": tmp},
            "loop": {"rate_hz": args.rate},
            # every tick publishes, so arrival -> publish is not stretched by decimation
            "zenoh": {"listen": [f"tcp/127.0.0.1:{port}"], "joints_rate_hz": pub_rate,
                      "live_rate_hz": pub_rate},
            "installation": vc["installation"], "devices": vc["devices"]})
        svc = Service(cfg, load_params(PARAMS), record_stats=True)
        svc.start(zenoh_wait_s=5.0)
        child.stdin.write(f"tcp/127.0.0.1:{port}\n")
        child.stdin.flush()
        assert child.stdout.readline().strip() == "subscribed"
        if not svc.wait_drivers(15.0):
            print("drivers not connected:", {n: d.health.last_error
                                              for n, d in svc.drivers.items()}, file=sys.stderr)
        stop = threading.Event()
        loop = threading.Thread(target=svc.run, args=(stop,), name="loop")
        time.sleep(1.0)
        cpu0, t0 = time.process_time(), time.monotonic()
        loop.start()
        time.sleep(args.seconds)
        stop.set()
        loop.join()
        cpu, wall = time.process_time() - cpu0, time.monotonic() - t0
        st = svc.loop_stats
        health = svc.health_msg or {}
        svc.close()
    child.stdin.write("\n")
    child.stdin.flush()
    sub = json.loads(child.stdout.readline())
    child.wait(10)
    late = st.all_late[int(args.rate):]  # skip the first second (start-up)
    res: dict[str, Any] = {
        "rate_hz": args.rate, "publish_rate_hz": pub_rate, "seconds": round(wall, 1),
        "ticks": st.ticks,
        "overruns": st.overruns, "skipped_ticks": st.skipped,
        "tick_jitter_ms": pct(late),
        "tick_work_ms": pct(st.all_work),
        "arrival_to_publish_ms": pct(svc.latency.all),
        "tick_to_subscriber_ms": {k: round(v, 3) if isinstance(v, float) else v
                                  for k, v in sub.items()},
        "cpu_percent_of_one_core": round(100.0 * cpu / wall, 1),
        "passes": svc.passes_written,
        "drivers": {n: {"rate_hz": d.get("rate_hz"), "state": d.get("state")}
                    for n, d in (health.get("drivers") or {}).items()},
    }
    if args.json:
        print(json.dumps(res))
    else:
        j, a, s = res["tick_jitter_ms"], res["arrival_to_publish_ms"], res["tick_to_subscriber_ms"]
        print(f"{res['seconds']} s at {args.rate:g} Hz: {res['ticks']} ticks, "
              f"{res['overruns']} overruns, {res['passes']} passes")
        print(f"tick jitter      p50 {j['p50']:.3f} ms  p99 {j['p99']:.3f} ms  max "
              f"{j['max']:.3f} ms")
        print(f"arrival->publish p50 {a['p50']:.3f} ms  p99 {a['p99']:.3f} ms  (n={a['n']})")
        print(f"tick->subscriber p50 {s['p50']:.3f} ms  p99 {s['p99']:.3f} ms  (other process)")
        print(f"tick work        p50 {res['tick_work_ms']['p50']:.3f} ms  p99 "
              f"{res['tick_work_ms']['p99']:.3f} ms")
        print(f"CPU              {res['cpu_percent_of_one_core']} % of one core")
        print(f"drivers          {res['drivers']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
