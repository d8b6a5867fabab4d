"""The CPU floor of the live daemon's I/O pattern, with no work done on any of it.

The daemon at 100 Hz reads 100 MTi packets and 50 laser lines a second, polls two
Modbus modules at 50 Hz each (a request after a timed sleep, then the answer) and
ticks 100 times a second. This bench makes exactly those events and nothing else: a
child process writes the packets and lines into pipes and echoes the polls on two
loopback TCP sockets; this process takes them in one of two shapes, alternating run by
run so that the machine's load hits both alike:

* ``threads``: a thread per device as the daemon has it (``select`` + ``os.read`` per
  serial wake-up, ``send`` + ``recv`` per poll after a sleep to its deadline) and a loop
  thread sleeping to each 10 ms deadline;
* ``selector``: one thread waiting on every descriptor and the next deadline (one
  ``epoll``), as gpsd reads all its devices;
* ``threads+puts``: the threads, and the loop thread puts ``--puts`` (default 2) small
  messages on Zenoh each tick, to a subscriber in the child (a peer session here, a
  client there, on loopback), as the daemon does with every tick published (``joints``
  and ``payload/live``): the floor of the issue's workload.

It prints the process's CPU as % of one core and its voluntary context switches a
second (the wake-ups), median and range over the runs. What the daemon costs above
this floor is its own work (``bench/daemon_live.py``); what a single-thread daemon
could save is the difference between the two shapes.

    .venv/bin/python bench/io_floor.py [--seconds 20] [--runs 3] [--puts 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import select
import selectors
import socket
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import TypedDict

from hil_fixtures.net import free_port

MTI_HZ, LASER_HZ, POLL_HZ, TICK_HZ = 100.0, 50.0, 50.0, 100.0
MTI_BYTES, LASER_BYTES, REQUEST_BYTES, ANSWER_BYTES = 80, 12, 12, 23

CHILD = r"""
import os, socket, sys, threading, time
mti_w, laser_w = int(sys.argv[1]), int(sys.argv[2])
mti_hz, laser_hz, mti_n, laser_n, answer_n = map(float, sys.argv[3:8])
servers = []
for _ in range(2):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    servers.append(s)
print(" ".join(str(s.getsockname()[1]) for s in servers), flush=True)

def echo(server):
    c, _ = server.accept()
    c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    try:
        while c.recv(256):
            c.send(b"a" * int(answer_n))
    except OSError:  # the measuring side closed its socket
        pass

def stream(fd, hz, n):
    t = time.monotonic()
    while True:
        t += 1.0 / hz
        time.sleep(max(0.0, t - time.monotonic()))
        os.write(fd, b"m" * int(n))

for s in servers:
    threading.Thread(target=echo, args=(s,), daemon=True).start()
threading.Thread(target=stream, args=(laser_w, laser_hz, laser_n), daemon=True).start()
if len(sys.argv) > 8:  # a Zenoh endpoint: subscribe to what the loop puts, like a cab
    import zenoh
    from shoveld.daemon.publisher import zenoh_config
    session = zenoh.open(zenoh_config("client", (), [sys.argv[8]]))
    sub = session.declare_subscriber("floor/**", lambda sample: None)
    print("subscribed", flush=True)
stream(mti_w, mti_hz, mti_n)
"""
MESSAGE = ('{"time":1764460800.123,"swing_deg":12.345,"handle_deg":-3.21,"crowd_m":7.1234,'
           '"boom_deg":45.0,"invalid":[]}')
"""A ``joints`` message's size."""


def voluntary_switches() -> int:
    """Voluntary context switches of this process, ended threads included: its
    wake-ups."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_nvcsw


def run_threads(fds: tuple[int, int], socks: list[socket.socket], until: float,
                pubs: tuple[object, ...] = ()) -> None:
    """A thread per device and a loop thread, as the daemon runs them; the loop puts a
    message on each of ``pubs`` (Zenoh publishers) every tick."""
    def loop() -> None:
        t = time.monotonic()
        while t < until:
            t += 1.0 / TICK_HZ
            time.sleep(max(0.0, t - time.monotonic()))
            for pub in pubs:
                pub.put(MESSAGE)  # type: ignore[attr-defined]

    def reader(fd: int) -> None:
        while time.monotonic() < until:
            if select.select((fd,), (), (), 0.1)[0]:
                os.read(fd, 4096)

    def poller(s: socket.socket, phase: float) -> None:
        t = time.monotonic() + phase
        while t < until:
            t += 1.0 / POLL_HZ
            time.sleep(max(0.0, t - time.monotonic()))
            s.send(b"q" * REQUEST_BYTES)
            s.recv(256)

    jobs: list[tuple[Callable[..., None], tuple[object, ...]]] = [
        (loop, ()), (reader, (fds[0],)), (reader, (fds[1],)),
        (poller, (socks[0], 0.0)), (poller, (socks[1], 0.003))]
    threads = [threading.Thread(target=f, args=a, daemon=True) for f, a in jobs]
    for th in threads:
        th.start()
    for th in threads:
        th.join()


def run_selector(fds: tuple[int, int], socks: list[socket.socket], until: float) -> None:
    """One thread: every descriptor and the next deadline in one ``epoll`` wait."""
    sel = selectors.DefaultSelector()
    for fd in fds:
        sel.register(fd, selectors.EVENT_READ, None)
    for s in socks:
        sel.register(s, selectors.EVENT_READ, s)
    now = time.monotonic()
    tick, poll = now + 1.0 / TICK_HZ, now + 1.0 / POLL_HZ
    while now < until:
        for key, _ in sel.select(max(0.0, min(tick, poll) - time.monotonic())):
            if key.data is None:
                os.read(key.fd, 4096)
            else:
                key.data.recv(256)
        now = time.monotonic()
        if now >= tick:
            tick += 1.0 / TICK_HZ
        if now >= poll:
            poll += 1.0 / POLL_HZ
            for s in socks:
                s.send(b"q" * REQUEST_BYTES)
    sel.close()


def one_run(shape: str, seconds: float, puts: int = 0) -> tuple[float, float]:
    """(% of one core, wake-ups a second) of this process over ``seconds``."""
    mti_r, mti_w = os.pipe()
    laser_r, laser_w = os.pipe()
    session = None
    argv = [sys.executable, "-c", CHILD, str(mti_w), str(laser_w), str(MTI_HZ), str(LASER_HZ),
            str(MTI_BYTES), str(LASER_BYTES), str(ANSWER_BYTES)]
    if shape == "threads+puts":
        import zenoh

        from shoveld.daemon.publisher import zenoh_config

        endpoint = f"tcp/127.0.0.1:{free_port()}"
        session = zenoh.open(zenoh_config("peer", [endpoint]))
        argv.append(endpoint)
    child = subprocess.Popen(argv, pass_fds=(mti_w, laser_w), stdout=subprocess.PIPE,
                             text=True)
    try:
        assert child.stdout is not None
        ports = [int(p) for p in child.stdout.readline().split()]
        socks = [socket.create_connection(("127.0.0.1", p)) for p in ports]
        for s in socks:
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        pubs: tuple[object, ...] = ()
        if session is not None:
            assert child.stdout.readline().strip() == "subscribed"
            pubs = tuple(session.declare_publisher(f"floor/{k}") for k in range(puts))
        if shape == "selector":
            def run(until: float) -> None:
                run_selector((mti_r, laser_r), socks, until)
        else:
            def run(until: float) -> None:
                run_threads((mti_r, laser_r), socks, until, pubs)
        run(time.monotonic() + 1.0)  # settle
        c0, w0, v0 = time.process_time(), time.monotonic(), voluntary_switches()
        run(w0 + seconds)
        c1, w1, v1 = time.process_time(), time.monotonic(), voluntary_switches()
        for s in socks:
            s.close()
        return 100.0 * (c1 - c0) / (w1 - w0), (v1 - v0) / (w1 - w0)
    finally:
        child.kill()
        child.wait()
        if session is not None:
            session.close()
        for fd in (mti_r, mti_w, laser_r, laser_w):
            os.close(fd)


class ShapeRuns(TypedDict):
    """One shape's figures, run by run."""

    cpu_pct: list[float]
    wakes_per_s: list[int]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--puts", type=int, default=2,
                    help="Zenoh puts a tick in the threads+puts shape (0: no such shape)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    got: dict[str, list[tuple[float, float]]] = {"threads": [], "selector": []}
    if args.puts > 0:
        got["threads+puts"] = []
    for _ in range(args.runs):
        for shape in got:
            got[shape].append(one_run(shape, args.seconds, args.puts))
    out: dict[str, ShapeRuns] = {
        shape: {"cpu_pct": [round(c, 2) for c, _ in v], "wakes_per_s": [round(w) for _, w in v]}
        for shape, v in got.items()}
    if args.json:
        print(json.dumps(out))
        return
    print(f"the daemon's I/O pattern, no work: MTi {MTI_HZ:g} Hz, laser {LASER_HZ:g} Hz, two "
          f"Modbus modules polled at {POLL_HZ:g} Hz, ticks at {TICK_HZ:g} Hz "
          f"(threads+puts: {args.puts} Zenoh puts a tick); "
          f"{args.runs} runs of {args.seconds:g} s each, alternating")
    for shape, v in out.items():
        c, w = v["cpu_pct"], v["wakes_per_s"]
        print(f"  {shape:<12s} {statistics.median(c):5.2f} % of one core "
              f"[{min(c):.2f}-{max(c):.2f}]   {statistics.median(w):5.0f} wake-ups/s "
              f"[{min(w)}-{max(w)}]")


if __name__ == "__main__":
    main()
