"""Replay speed of the daemon on the committed capture, as a multiple of real time.

* ``fast``: ``shoveld replay --fast`` in-process - the bulk front end (each device's
  driver on its in-memory transport, alone over a span of ticks, with its span reads;
  the span's samples built with numpy), then the loop: engine, pass log, Zenoh. The
  breakdown splits the time per 10 ms tick into the front end (per device: its steps
  and span reads with their bookkeeping; and the assembly) and the loop
  (engine, and the rest: service, events, health); ``loop only`` is the speed of the
  loop without the front end;
* ``per-tick``: the same with the drivers, store and assembler inside every tick
  (``fast_replay_service(..., bulk=False)``, the live daemon's order of work), run
  interleaved with ``fast`` so both see the same machine;
* ``--command``: the whole ``shoveld replay CAPTURE --fast`` as a subprocess (start,
  imports, reading the capture, Zenoh session, the replay, shutdown), wall time;
  ``--stages``: the same stages in a fresh interpreter, each timed (where that wall
  time goes);
* ``stepped``: the drivers in their threads on the drivers' virtual hardware (ptys,
  pymodbus TCP servers) on the stepped replay clock.

Startup (imports, Zenoh session) is not counted in ``fast`` and ``per-tick``; the
figure is capture seconds played per wall second of ``ReplayRun.run`` (which includes
the bulk front end: it works a span ahead of the ticks), the median of ``--repeat``
runs (the machine is shared: the spread is printed too). Nobody subscribes by
default, so the loop topics (joints, live payload, health) are not encoded;
``--subscriber`` adds a Zenoh subscriber to every topic in this process, as a cab
watching the replay would be.

Usage: ``.venv/bin/python bench/daemon_replay.py [--repeat 5] [--command] [--stages]
[--stepped] [--subscriber] [--json]``
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

from hil_fixtures.net import free_port

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


def run_once(stepped: bool, breakdown: bool, subscriber: bool = False, bulk: bool = True
             ) -> dict[str, Any]:
    from shoveld.daemon.config import parse_config
    from shoveld.model.params import load_params
    from shoveld.replay.bulk import BulkAssembler
    from shoveld.replay.service import fast_replay_service, replay_service

    port = free_port()
    listen = [f"tcp/127.0.0.1:{port}"] if subscriber else []
    with tempfile.TemporaryDirectory() as tmp:
        cfg = parse_config({"shovel": {"id": "bench", "params": str(PARAMS), "state_dir": tmp},
                            "zenoh": {"listen": listen}, "truck": {"target_kg": 62000.0}},
                           require_devices=False)
        params = load_params(PARAMS)
        rr = (replay_service(CAPTURE, cfg, params, None) if stepped
              else fast_replay_service(CAPTURE, cfg, params, bulk=bulk))
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
                # Timing wrappers shadow the methods on these instances (method-assign).
                assert svc.engine is not None
                svc.engine.step = timed(  # type: ignore[method-assign]
                    acc, "engine", svc.engine.step)
                svc.publisher.put = timed(  # type: ignore[method-assign]
                    acc, "zenoh put", svc.publisher.put)
                if bulk:
                    assert isinstance(svc.assembler, BulkAssembler)
                    feed = svc.assembler.feed
                    feed._run_device = timed_by_device(  # type: ignore[method-assign]
                        acc, feed._run_device)
                    feed._assemble = timed(  # type: ignore[method-assign]
                        acc, "  assembly (numpy)", feed._assemble)
                    feed.spans = timed_spans(  # type: ignore[method-assign]
                        acc, "front end (drivers, assembly)", feed.spans)
                    svc.assembler._spans = feed.spans()
                else:
                    for dev in rr.session._devs:
                        dev.step = timed(acc, f"  driver {dev.name}", dev.step)
                    assert svc.before_tick is not None  # the per-tick replay's drivers' step
                    svc.before_tick = timed(acc, "drivers (parse, health)", svc.before_tick)
                    svc.assembler.sample = timed(  # type: ignore[method-assign]
                        acc, "assemble", svc.assembler.sample)
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
        front = acc.get("front end (drivers, assembly)")
        if front is not None:
            fig["loop_only_speed_x"] = round(fig["capture_s"] / (total - front), 1)
    return fig


def timed_by_device(acc: dict[str, float], run: Callable[..., Any]) -> Callable[..., Any]:
    """``BulkFeed._run_device`` (a device's ticks of a span: its per-tick steps and
    span reads) with the time counted per device."""
    def wrapper(name: str, *a: Any) -> Any:
        return timed(acc, f"  driver {name}", run)(name, *a)
    return wrapper


def timed_spans(acc: dict[str, float], name: str, spans: Callable[[], Any]
                ) -> Callable[[], Any]:
    """``spans`` (a generator function) with the time spent making each span counted."""
    def wrapper() -> Any:
        it = spans()
        while True:
            t0 = time.perf_counter()
            try:
                span = next(it)
            except StopIteration:
                return
            finally:
                acc[name] = acc.get(name, 0.0) + time.perf_counter() - t0
            yield span
    return wrapper


def run_command(repeat: int) -> dict[str, Any]:
    """Wall time of the whole ``shoveld replay CAPTURE --fast`` command, ``repeat`` runs."""
    import statistics
    import subprocess
    import sys

    walls = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "shoveld", "replay", str(CAPTURE), "--fast",
                        "--listen", f"tcp/127.0.0.1:{free_port()}"], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
        walls.append(time.perf_counter() - t0)
    from drivers.capture.format import read_capture

    capture_s = read_capture(CAPTURE).duration_s()
    med = statistics.median(walls)
    return {"wall_s": round(med, 3), "all_wall_s": [round(w, 3) for w in walls],
            "speed_x": round(capture_s / med, 1),
            "all_speed_x": [round(capture_s / w, 1) for w in walls]}


# The stages of ``shoveld replay CAPTURE --fast`` in a fresh interpreter, in the
# command's own order (shoveld.cli.replay.run), each timed: what the whole command's
# wall time is made of.
_STAGES = r"""
import json, os, sys, time
t0 = time.perf_counter()
marks = []
def mark(name):
    marks.append((name, time.perf_counter()))
import argparse, gc, tempfile, threading
from pathlib import Path
from shoveld.cli.common import one_blas_thread
one_blas_thread()
mark("the command line's modules")
gc.disable()
import numpy
mark("numpy")
from drivers.capture.format import CaptureFormatError
from shoveld.daemon.logs import setup_logging
from shoveld.payload.trucks import truck_line
from shoveld.replay.service import fast_replay_service
gc.enable()
mark("the daemon's own modules")
from shoveld.cli.replay import build_config
ns = argparse.Namespace(capture=sys.argv[1], fast=True, config=None, params=None, mode=None,
                        listen=[sys.argv[2]], connect=None, id=None, state_dir=None)
tmp = tempfile.TemporaryDirectory()
cfg, params = build_config(ns, Path(tmp.name))
mark("the config and params")
rr = fast_replay_service(ns.capture, cfg, params)
mark("reading the capture, building the service")
rr.service.durable_pass_log = False
rr.service.start(zenoh_wait_s=2.0)
mark("the Zenoh session")
rr.run(threading.Event())
mark("the play")
rr.service.flush()
rr.close()
tmp.cleanup()
mark("the end (pass log, Zenoh, temporary folder)")
out, prev = [], t0
for name, t in marks:
    out.append([name, t - prev])
    prev = t
print(json.dumps({"stages": out, "in_process_s": prev - t0}))
sys.stdout.flush()
os._exit(0)
"""


def run_stages(repeat: int) -> dict[str, Any]:
    """The whole command's stages (``_STAGES``), medians of ``repeat`` fresh interpreters;
    the interpreter's own start and exit is the wall time less the time inside."""
    import statistics
    import subprocess
    import sys

    runs, outside = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-c", _STAGES, str(CAPTURE),
                            f"tcp/127.0.0.1:{free_port()}"], check=True, capture_output=True,
                           text=True, cwd=ROOT)
        wall = time.perf_counter() - t0
        d = json.loads(r.stdout.strip().splitlines()[-1])
        runs.append(dict(d["stages"]))
        outside.append(wall - d["in_process_s"])
    names = list(runs[0])
    out = {"the interpreter's start and exit": statistics.median(outside)}
    out |= {n: statistics.median(r[n] for r in runs) for n in names}
    return {k: round(v, 4) for k, v in out.items()}


def _summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    med = sorted(runs, key=lambda r: r["speed_x"])[len(runs) // 2]
    return {"speed_x": med["speed_x"], "all_speed_x": [r["speed_x"] for r in runs],
            "capture_s": med["capture_s"], "real_s": med["real_s"],
            "cpu_s": med["cpu_s"], "passes_kg": med["passes_kg"],
            "messages_received": med["messages_received"],
            "same_passes_every_run": all(r["passes_kg"] == runs[0]["passes_kg"]
                                         for r in runs)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--command", action="store_true",
                    help="also the whole command (subprocess), --repeat runs")
    ap.add_argument("--stages", action="store_true",
                    help="also the whole command's stages, each timed (medians of --repeat)")
    ap.add_argument("--stepped", action="store_true", help="also the threaded stepped replay")
    ap.add_argument("--subscriber", action="store_true",
                    help="a Zenoh subscriber to every topic (the loop topics are then encoded)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    out: dict[str, Any] = {}
    # the whole command first: after the in-process replays below the same command read
    # 10-30 ms slower (2026-11-29), a state of the machine no user starts it in
    if args.command:
        out["command"] = run_command(args.repeat)
    if args.stages:
        out["command_stages_s"] = run_stages(args.repeat)
    bulk, per_tick = [], []
    for _ in range(args.repeat):  # interleaved: a burst of load hits both alike
        bulk.append(run_once(False, False, args.subscriber))
        per_tick.append(run_once(False, False, args.subscriber, bulk=False))
    out["fast"] = _summary(bulk)
    out["per_tick"] = _summary(per_tick)
    out["same_passes_bulk_and_per_tick"] = out["fast"]["passes_kg"] == out["per_tick"]["passes_kg"]
    b = run_once(False, True, args.subscriber)
    out["fast_breakdown_us_per_tick"] = b["us_per_tick"]
    out["fast_loop_only_speed_x"] = b["loop_only_speed_x"]
    out["per_tick_breakdown_us_per_tick"] = run_once(False, True, args.subscriber,
                                                     bulk=False)["us_per_tick"]
    if args.stepped:
        r = run_once(True, False)
        out["stepped_threaded"] = {k: r[k] for k in ("speed_x", "capture_s", "real_s",
                                                     "cpu_s", "passes_kg")}
    if args.json:
        print(json.dumps(out))
        return 0
    for key, what in (("fast", "fast replay (bulk front end)"),
                      ("per_tick", "fast replay, drivers in each tick")):
        f = out[key]
        print(f"{what}: {f['speed_x']}x real time (median; runs {f['all_speed_x']}), "
              f"{f['capture_s']} s of capture in {f['real_s']} s, {f['cpu_s']} s CPU; "
              f"passes {f['passes_kg']}, identical every run: {f['same_passes_every_run']}"
              + (f"; {f['messages_received']} messages to the subscriber" if args.subscriber
                 else ""))
    print(f"same passes both ways: {out['same_passes_bulk_and_per_tick']}")
    print("per 10 ms tick, bulk (us, one more run with timers around each stage; the loop "
          f"alone, without the front end: {out['fast_loop_only_speed_x']}x):")
    for k, v in out["fast_breakdown_us_per_tick"].items():
        print(f"  {v:7.1f}  {k}")
    print("per 10 ms tick, drivers in each tick (us):")
    for k, v in out["per_tick_breakdown_us_per_tick"].items():
        print(f"  {v:7.1f}  {k}")
    if "command" in out:
        c = out["command"]
        print(f"whole command (shoveld replay --fast, subprocess): {c['speed_x']}x real time, "
              f"{c['wall_s']} s (median; runs {c['all_wall_s']} s)")
    if "command_stages_s" in out:
        st = out["command_stages_s"]
        print(f"the whole command's stages (s, medians of {args.repeat} fresh interpreters; "
              f"sum {sum(st.values()):.3f} s):")
        for k, v in st.items():
            print(f"  {v:7.3f}  {k}")
    if "stepped_threaded" in out:
        s = out["stepped_threaded"]
        print(f"stepped threaded replay (ptys, Modbus servers, driver threads): "
              f"{s['speed_x']}x real time, passes {s['passes_kg']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
