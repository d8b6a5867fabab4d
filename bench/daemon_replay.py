"""Replay speed of the daemon on the committed capture, as a multiple of real time.

* ``fast``: ``shoveld replay --fast`` in-process - the drivers' code on in-memory
  transports stepped by the loop, then store, assembly, engine, pass log, Zenoh; with a
  per-stage breakdown of the time per 10 ms tick;
* ``stepped``: the drivers in their threads on the drivers' virtual hardware (ptys,
  pymodbus TCP servers) on the stepped replay clock;

Startup (imports, Zenoh session) is not counted; the figure is capture seconds played
per wall second of the loop, the median of ``--repeat`` runs (the machine is shared:
the spread is printed too). Nobody subscribes by default, so the loop topics (joints,
live payload, health) are not encoded; ``--subscriber`` adds a Zenoh subscriber to every
topic in this process, as a cab watching the replay would be.

Usage: ``.venv/bin/python bench/daemon_replay.py [--repeat 5] [--stepped] [--subscriber]
[--json]``
"""

from __future__ import annotations

import argparse
import json
import logging
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CAPTURE = ROOT / "hil_fixtures" / "captures" / "daemon-e2e"
PARAMS = CAPTURE / "params.toml"


def timed(acc: dict[str, float], name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
    def wrapper(*a: Any, **k: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            acc[name] = acc.get(name, 0.0) + time.perf_counter() - t0
    return wrapper


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run_once(stepped: bool, breakdown: bool, subscriber: bool = False) -> dict[str, Any]:
    from shoveld.daemon.config import parse_config
    from shoveld.daemon.replay import fast_replay_service, replay_service
    from shoveld.model.params import load_params

    port = free_port()
    listen = [f"tcp/127.0.0.1:{port}"] if subscriber else []
    with tempfile.TemporaryDirectory() as tmp:
        cfg = parse_config({"shovel": {"id": "bench", "params": str(PARAMS), "state_dir": tmp},
                            "zenoh": {"listen": listen}, "truck": {"target_kg": 62000.0}},
                           require_devices=False)
        params = load_params(PARAMS)
        rr = (replay_service(CAPTURE, cfg, params, None) if stepped
              else fast_replay_service(CAPTURE, cfg, params))
        svc = rr.service
        acc: dict[str, float] = {}
        passes: list[float] = []
        svc.on_event = lambda k, m: passes.append(m["payload_kg"]) if k == "pass" else None
        sub_session = None
        received = [0]
        try:
            svc.start(zenoh_wait_s=5.0)
            if subscriber:
                import zenoh

                from shoveld.daemon.publisher import zenoh_config

                sub_session = zenoh.open(zenoh_config("client", (), [listen[0]]))
                sub_session.declare_subscriber(
                    "shovel/bench/**", lambda s: received.__setitem__(0, received[0] + 1))
                time.sleep(0.5)  # the subscription reaches the daemon
            if breakdown and not stepped:
                for dev in rr.session._devs:
                    dev.step = timed(acc, f"  driver {dev.name}", dev.step)
                svc.before_tick = timed(acc, "drivers (parse, health)", svc.before_tick)
                svc.assembler.sample = timed(acc, "assemble", svc.assembler.sample)
                assert svc.engine is not None
                svc.engine.step = timed(acc, "engine", svc.engine.step)
                svc.publisher.put = timed(acc, "zenoh put", svc.publisher.put)
            fig = rr.run(threading.Event())
            svc.flush()
        finally:
            rr.close()
            if sub_session is not None:
                sub_session.close()
    fig["passes_kg"] = passes
    fig["messages_received"] = received[0]
    if acc:
        total = fig["real_s"]
        fig["us_per_tick"] = {k: round(1e6 * v / fig["ticks"], 1) for k, v in acc.items()}
        fig["us_per_tick"]["rest (loop, events, health)"] = round(
            1e6 * (total - sum(v for k, v in acc.items() if not k.startswith(" ")))
            / fig["ticks"], 1)
    return fig


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--stepped", action="store_true", help="also the threaded stepped replay")
    ap.add_argument("--subscriber", action="store_true",
                    help="a Zenoh subscriber to every topic (the loop topics are then encoded)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    out: dict[str, Any] = {}
    runs = [run_once(False, False, args.subscriber) for _ in range(args.repeat)]
    med = sorted(runs, key=lambda r: r["speed_x"])[len(runs) // 2]
    out["fast"] = {"speed_x": med["speed_x"], "all_speed_x": [r["speed_x"] for r in runs],
                   "capture_s": med["capture_s"], "real_s": med["real_s"],
                   "cpu_s": med["cpu_s"], "passes_kg": med["passes_kg"],
                   "messages_received": med["messages_received"],
                   "same_passes_every_run": all(r["passes_kg"] == runs[0]["passes_kg"]
                                                for r in runs)}
    out["fast_breakdown_us_per_tick"] = run_once(False, True, args.subscriber)["us_per_tick"]
    if args.stepped:
        r = run_once(True, False)
        out["stepped_threaded"] = {k: r[k] for k in ("speed_x", "capture_s", "real_s",
                                                     "cpu_s", "passes_kg")}
    if args.json:
        print(json.dumps(out))
        return 0
    f = out["fast"]
    print(f"fast replay: {f['speed_x']}x real time (median; runs {f['all_speed_x']}), "
          f"{f['capture_s']} s of capture in {f['real_s']} s, {f['cpu_s']} s CPU; "
          f"passes {f['passes_kg']}, identical every run: {f['same_passes_every_run']}"
          + (f"; {f['messages_received']} messages to the subscriber" if args.subscriber
             else ""))
    print("per 10 ms tick (us, one more run with timers around each stage):")
    for k, v in out["fast_breakdown_us_per_tick"].items():
        print(f"  {v:7.1f}  {k}")
    if "stepped_threaded" in out:
        s = out["stepped_threaded"]
        print(f"stepped threaded replay (ptys, Modbus servers, driver threads): "
              f"{s['speed_x']}x real time, passes {s['passes_kg']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
