"""Daemon live figures at 100 Hz: tick jitter, arrival-to-publish latency, CPU per second.

Two processes, like a shovel: this one runs the daemon exactly as ``shoveld run``
does (``Service`` on the host monotonic clock, one thread per driver, Zenoh peer on
loopback); a child process runs the virtual shovel's emulators (MTi at 100 Hz on a pty,
AR4000 at 50 Hz on a pty, two Modbus TCP modules) and a Zenoh subscriber that timestamps
every ``joints`` message it receives. Figures:

* tick jitter: wake-up lateness against each absolute deadline (p50, p99, max);
* arrival -> publish: from a reading reaching the daemon's store to the put of the
  first message computed from it (``joints`` for the arm sensors and the boom
  inclinometer, ``payload/live`` for the motor currents), for the phase-lock master
  (``--sync``, default the MTi) and for the other sensors separately, and per device.
  The Modbus modules are polled by the host, so with ``[loop] align_polls`` (on with
  ``sync``; ``--no-align-polls`` for the comparison) each poll starts its measured round
  trip before a tick and its answer lands just before it. The AR4000 laser streams on
  its own free-running sample clock (no documented trigger or sync input), so its
  readings wait anywhere from 0 to one loop period (10 ms) for a tick, and nothing on
  the host can change that;
* tick -> subscriber: from the tick's deadline to the other process receiving the
  ``joints`` message (processing + Zenoh over loopback); the other process subscribes
  to every topic, like a cab, so nothing is skipped for want of a subscriber;
* CPU: this process's CPU seconds per second (drivers, loop, engine, Zenoh), and per
  thread (``/proc/self/task/*/schedstat``: driver threads, the loop, Zenoh's threads);
* ``--profile``: py-spy (``pip install py-spy``) samples the thread holding the GIL
  during the run and the top functions are printed (``--profile-out`` keeps the raw
  samples; ``--flame SVG`` writes py-spy's flame graph of the same seconds).

Usage: ``.venv/bin/python bench/daemon_live.py [--seconds 60] [--sync mti|none]
[--publish-rate 10] [--no-align-polls] [--poll-hz adc_incl=20] [--profile [--flame SVG]]
[--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from hil_fixtures.net import free_port

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
    def on(sample):  # every topic, like a cab; latency from the joints messages
        now = time.time()
        msg = json.loads(sample.payload.to_bytes())
        if str(sample.key_expr).endswith("/joints"):
            lat.append(now - msg["time"])
    sub = s.declare_subscriber("shovel/bench/**", on)
    print("subscribed", flush=True)
    sys.stdin.readline()
    sub.undeclare()
    s.close()
v = np.array(lat[50:]) * 1e3
print(json.dumps({"n": len(v), "p50": float(np.percentile(v, 50)),
                  "p99": float(np.percentile(v, 99)), "max": float(v.max())}), flush=True)
"""


def pct(v: list[float] | np.ndarray, scale: float = 1e3) -> dict[str, float]:
    a = np.asarray(v) * scale
    return {"p50": round(float(np.percentile(a, 50)), 3), "p99": round(float(np.percentile(a,
                                                                                        99)), 3),
            "max": round(float(a.max()), 3), "n": int(a.size)}


def thread_cpu_s() -> dict[int, float]:
    """CPU seconds of every thread of this process so far (kernel scheduler statistics)."""
    out: dict[int, float] = {}
    for task in Path("/proc/self/task").iterdir():
        try:
            out[int(task.name)] = int((task / "schedstat").read_text().split()[0]) / 1e9
        except (OSError, ValueError, IndexError):
            pass
    return out


def thread_names() -> dict[int, str]:
    names = {t.native_id: t.name for t in threading.enumerate() if t.native_id is not None}
    for task in Path("/proc/self/task").iterdir():
        tid = int(task.name)
        if tid not in names:
            try:
                names[tid] = "native:" + (task / "comm").read_text().strip()
            except OSError:
                names[tid] = f"native:{tid}"
    return names


def cpu_by_thread(before: dict[int, float], after: dict[int, float], wall: float
                  ) -> dict[str, float]:
    """Percent of one core per thread name (Zenoh's native threads grouped by name)."""
    names = thread_names()
    out: dict[str, float] = {}
    for tid, t1 in after.items():
        name = names.get(tid, f"native:{tid}")
        if name.startswith("native:"):
            name = "zenoh/native " + name[7:].rstrip("0123456789-_")
        out[name] = out.get(name, 0.0) + 100.0 * (t1 - before.get(tid, 0.0)) / wall
    return {k: round(v, 2) for k, v in sorted(out.items(), key=lambda kv: -kv[1])
            if v >= 0.005}


def start_py_spy(seconds: float, out: str, fmt: str = "raw"
                 ) -> subprocess.Popen[bytes] | None:
    # beside the interpreter (installed in its venv), else $PY_SPY or on the PATH
    exe = Path(sys.executable).with_name("py-spy")
    if not exe.exists():
        import shutil

        exe = Path(os.environ.get("PY_SPY") or shutil.which("py-spy") or exe)
    if not exe.exists():
        print("--profile: py-spy not installed (pip install py-spy)", file=sys.stderr)
        return None
    return subprocess.Popen([str(exe), "record", "-p", str(os.getpid()), "-d",
                             str(max(1, int(seconds))), "-r", "250", "--gil", "--threads",
                             "--nonblocking", "-f", fmt, "-o", out],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def summarize_py_spy(path: str, top: int = 25) -> list[tuple[float, str]]:
    """Inclusive share of the GIL-holding samples per function (thread names kept)."""
    import collections
    import re

    total = 0
    incl: collections.Counter[str] = collections.Counter()
    for line in Path(path).read_text().splitlines():
        stack, _, n = line.rpartition(" ")
        if not stack:
            continue
        count = int(n)
        total += count
        frames = stack.split(";")
        thread = frames[0].rsplit(":", 1)[-1].strip().strip('"')
        seen = {f"[thread {thread}]"}
        incl[f"[thread {thread}]"] += count
        for fr in frames[1:]:
            key = re.sub(r" \((?:.*/site-packages/|.*/python3\.\d+/|" + re.escape(str(ROOT))
                         + r"/)?(.*?):\d+\)$", r" (\1)", fr)
            if key not in seen:
                seen.add(key)
                incl[key] += count
    return [(round(100.0 * v / total, 1), k) for k, v in incl.most_common(top)] if total else []


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--publish-rate", type=float, default=None,
                    help="joints and live payload rate (default: every tick, so the latency "
                         "figure is not stretched by decimation; the service default is 10)")
    ap.add_argument("--sync", default="mti",
                    help="[loop] sync: the device the ticks are phase-locked to, or 'none'")
    ap.add_argument("--sync-delay", type=float, default=0.001, help="[loop] sync_delay_s")
    ap.add_argument("--no-align-polls", action="store_true",
                    help="[loop] align_polls = false: Modbus polls on their own schedule")
    ap.add_argument("--profile", action="store_true", help="py-spy the run (GIL holder)")
    ap.add_argument("--profile-out", default=None, help="keep py-spy's raw samples here")
    ap.add_argument("--flame", default=None, metavar="SVG",
                    help="with --profile: also a flame graph of the same seconds (py-spy's "
                         "own SVG, a second sampler beside the first)")
    ap.add_argument("--poll-hz", action="append", default=[], metavar="DEVICE=HZ",
                    help="a Modbus module's poll rate (default: the virtual shovel's 50 Hz "
                         "for both; examples/shoveld.toml polls adc_incl at 20)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    poll_hz: dict[str, float] = {}
    for item in args.poll_hz:
        name, _, hz = item.partition("=")
        try:
            value = float(hz)
        except ValueError:
            value = float("nan")
        if not value > 0:
            ap.error(f"--poll-hz {item!r}: expected DEVICE=HZ with HZ > 0")
        poll_hz[name] = value

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
    for name, hz in poll_hz.items():
        if name not in vc["devices"] or "poll_hz" not in vc["devices"][name]:
            child.kill()
            ap.error(f"--poll-hz: {name!r} is not a polled device of the virtual shovel "
                     f"({', '.join(n for n, d in vc['devices'].items() if 'poll_hz' in d)})")
        vc["devices"][name]["poll_hz"] = hz
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        cfg = parse_config({
            "shovel": {"id": "bench", "params": str(PARAMS), "state_dir": tmp},
            "loop": {"rate_hz": args.rate, "sync": args.sync,
                     "sync_delay_s": args.sync_delay, "align_polls": not args.no_align_polls},
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
        loop.start()
        time.sleep(2.0)  # the phase lock acquires; start-up is not measured
        for st_ in [svc.latency, *svc.latency_by_device.values()]:
            st_.all.clear()
        prof_out = args.profile_out or os.path.join(tmp, "py-spy.raw")
        spy = start_py_spy(args.seconds, prof_out) if args.profile else None
        flame = (start_py_spy(args.seconds, args.flame, "flamegraph")
                 if args.profile and args.flame else None)
        master = args.sync if args.sync in svc.latency_by_device else "mti"
        stored0 = svc.store.count(master)
        cpu0, t0, threads0 = time.process_time(), time.monotonic(), thread_cpu_s()
        time.sleep(args.seconds)
        cpu, wall = time.process_time() - cpu0, time.monotonic() - t0
        stored = svc.store.count(master) - stored0
        threads = cpu_by_thread(threads0, thread_cpu_s(), wall)
        stop.set()
        loop.join()
        profile = None
        if flame is not None:
            flame.wait(30)
        if spy is not None:
            spy.wait(30)
            profile = summarize_py_spy(prof_out) if os.path.exists(prof_out) else None
        st = svc.loop_stats
        health = svc.health_msg or {}
        svc.close()
    child.stdin.write("\n")
    child.stdin.flush()
    sub = json.loads(child.stdout.readline())
    child.wait(10)
    late = st.all_late[2 * int(args.rate):]  # skip the first two seconds (start-up)
    others = [x for n, ls in svc.latency_by_device.items() if n != master for x in ls.all]
    res: dict[str, Any] = {
        "rate_hz": args.rate, "publish_rate_hz": pub_rate, "seconds": round(wall, 1),
        "poll_hz": {n: d["poll_hz"] for n, d in vc["devices"].items() if "poll_hz" in d},
        "ticks": st.ticks,
        "overruns": st.overruns, "skipped_ticks": st.skipped,
        "tick_jitter_ms": pct(late),
        "tick_work_ms": pct(st.all_work),
        "arrival_to_publish_ms": pct(svc.latency.all),
        "arrival_to_publish_master_ms": {"device": master,
                                         **pct(svc.latency_by_device[master].all)},
        # readings superseded by a newer one before any tick used them have no latency
        "master_readings_never_used": max(0, stored - len(svc.latency_by_device[master].all)),
        "arrival_to_publish_others_ms": pct(others),
        "arrival_to_publish_by_device_ms": {n: pct(ls.all) for n, ls in
                                            svc.latency_by_device.items() if ls.all},
        "sync": (health.get("loop") or {}).get("sync"),
        "tick_to_subscriber_ms": {k: round(v, 3) if isinstance(v, float) else v
                                  for k, v in sub.items()},
        "cpu_percent_of_one_core": round(100.0 * cpu / wall, 1),
        "cpu_percent_by_thread": threads,
        "passes": svc.passes_written,
        "drivers": {n: {"rate_hz": d.get("rate_hz"), "state": d.get("state")}
                    for n, d in (health.get("drivers") or {}).items()},
        "align_polls": {n: d["align"] for n, d in (health.get("drivers") or {}).items()
                        if "align" in d},
    }
    if profile is not None:
        res["profile_gil_percent"] = profile
    if args.json:
        print(json.dumps(res))
    else:
        j, a, s = res["tick_jitter_ms"], res["arrival_to_publish_ms"], res["tick_to_subscriber_ms"]
        print(f"{res['seconds']} s at {args.rate:g} Hz: {res['ticks']} ticks, "
              f"{res['overruns']} overruns, {res['passes']} passes; topics at {pub_rate:g} Hz, "
              f"Modbus polls {res['poll_hz']}")
        print(f"tick jitter      p50 {j['p50']:.3f} ms  p99 {j['p99']:.3f} ms  max "
              f"{j['max']:.3f} ms")
        print(f"arrival->publish p50 {a['p50']:.3f} ms  p99 {a['p99']:.3f} ms  (n={a['n']}, "
              "all sensors)")
        m, o = res["arrival_to_publish_master_ms"], res["arrival_to_publish_others_ms"]
        print(f"  master {m['device']:<8} p50 {m['p50']:.3f} ms  p99 {m['p99']:.3f} ms  "
              f"(n={m['n']}, sync {args.sync}; {res['master_readings_never_used']} superseded "
              "before a tick used them)")
        print(f"  others          p50 {o['p50']:.3f} ms  p99 {o['p99']:.3f} ms  (n={o['n']}, "
              "not locked; Modbus polls aligned unless --no-align-polls)")
        for n, d in res["arrival_to_publish_by_device_ms"].items():
            print(f"    {n:<12} p50 {d['p50']:.3f} ms  p99 {d['p99']:.3f} ms")
        print(f"phase lock       {res['sync']}")
        for n, d in res["align_polls"].items():
            print(f"aligned polls    {n}: {d}")
        print(f"tick->subscriber p50 {s['p50']:.3f} ms  p99 {s['p99']:.3f} ms  (other process)")
        print(f"tick work        p50 {res['tick_work_ms']['p50']:.3f} ms  p99 "
              f"{res['tick_work_ms']['p99']:.3f} ms")
        print(f"CPU              {res['cpu_percent_of_one_core']} % of one core; by thread "
              f"{res['cpu_percent_by_thread']}")
        print(f"drivers          {res['drivers']}")
        if profile:
            print("py-spy, share of GIL-holding samples (inclusive):")
            for share, name in profile:
                print(f"  {share:5.1f} %  {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
