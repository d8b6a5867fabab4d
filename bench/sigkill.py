"""Crash safety: the daemon killed with SIGKILL at random moments, restarted on the same
pass log, and the log audited after every kill.

Each run is ``shoveld replay CAPTURE --fast --json`` (the whole daemon: real drivers,
loop, engine, pass log, Zenoh on loopback) on one state folder kept across the runs, as
a shovel's computer keeps its pass log across power cuts. The moment of each kill is
one of four kinds, drawn in turn:

* start-up: before the first pass (the log opened, the truck restored);
* in a pass: at a random moment of the run;
* in a commit: a few milliseconds after a pass was reported, as the next pass or its
  truck is being written;
* shut-down: after the capture's last pass, while the last truck is closed and the
  service stops (drawn within the shortest shut-down of five reference runs).

A run that ends by itself before its kill is audited like the others, and its kind is
drawn again, so that ``--kills`` kills land; the count of such runs is printed.

After each kill, and after a final complete run, it checks (``persist.audit_log``):
SQLite's ``integrity_check``; pass numbers 1..n and truck numbers with no gap; at most
the newest truck open; every pass the run reported (it is reported after its commit)
in the log with the same truck and payload (else: lost); no pass of one run written
twice (else: duplicated); and that the next run restored the open truck exactly as the
log held it.

    .venv/bin/python bench/sigkill.py [--kills 100] [--seed 1]

Goal (issue 12): 0 lost, 0 duplicated, 0 integrity or numbering faults.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import re
import signal
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

from hil_fixtures.net import free_port

ROOT = Path(__file__).resolve().parents[1]
CAPTURE = ROOT / "hil_fixtures" / "captures" / "daemon-e2e"
KINDS = ("start-up", "in a pass", "in a commit", "shut-down")




class Run:
    """One replay process; its reported passes, as they come."""

    def __init__(self, state: Path) -> None:
        cmd = [sys.executable, "-m", "shoveld", "-v", "replay", str(CAPTURE), "--fast",
               "--json", "--state-dir", str(state), "--zenoh-wait", "0",
               "--listen", f"tcp/127.0.0.1:{free_port()}"]
        self.t0 = time.monotonic()
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.passes: list[dict[str, Any]] = []
        self.events: list[tuple[float, str]] = []
        self.err = ""
        self.ended = math.nan
        """When ``finish`` saw the process gone (the reference run's end: it waits at once)."""
        self._err_parts: list[str] = []
        # stdout and stderr each read by a thread to the end: ``communicate`` would read
        # stdout too, racing the event reader for a fast run's lines (the reference run
        # then had no passes, one run in a few)
        self._out = threading.Thread(target=self._read, daemon=True)
        self._err = threading.Thread(target=self._read_err, daemon=True)
        self._out.start()
        self._err.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                msg = json.loads(line)
            except ValueError:
                continue
            self.events.append((time.monotonic(), str(msg.get("topic"))))
            if msg.get("topic") == "pass":
                self.passes.append(msg)

    def _read_err(self) -> None:
        assert self.proc.stderr is not None
        self._err_parts.append(self.proc.stderr.read())

    def wait_passes(self, n: int, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end and self.proc.poll() is None:
            if len(self.passes) >= n:
                return True
            time.sleep(0.001)
        return len(self.passes) >= n

    def kill(self) -> bool:
        """SIGKILL; True if the process was still running."""
        alive = self.proc.poll() is None
        if alive:
            self.proc.send_signal(signal.SIGKILL)
        return alive

    def finish(self, timeout: float = 120.0) -> int:
        self.proc.wait(timeout=timeout)
        self.ended = time.monotonic()
        self._out.join(5.0)
        self._err.join(5.0)
        self.err = "".join(self._err_parts)
        return int(self.proc.returncode)


def rows(state: Path) -> dict[int, tuple[int, float | None, float]]:
    """pass -> (truck, payload, start) of the log."""
    path = state / "passes.sqlite"
    if not path.exists():
        return {}
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        if not con.execute("SELECT 1 FROM sqlite_master WHERE name = 'passes'").fetchone():
            return {}
        return {int(p): (int(t), kg, float(s)) for p, t, kg, s in con.execute(
            "SELECT pass, truck, payload_kg, start_unix FROM passes")}
    finally:
        con.close()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--kills", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    from shoveld.daemon.persist import audit_log

    rng = random.Random(args.seed)
    faults: Counter[str] = Counter()
    kinds: Counter[str] = Counter()
    missed: Counter[str] = Counter()
    with tempfile.TemporaryDirectory() as tmp:
        # A complete run on its own folder: the timings the kill moments are drawn from.
        ref = Run(Path(tmp) / "ref")
        assert ref.finish() == 0, ref.err
        first = next(t for t, topic in ref.events if topic == "pass") - ref.t0
        run_s = ref.events[-1][0] - ref.t0
        # from the last pass reported to the process's end: the last truck closed, the
        # service stopped (10-50 ms since the replay got fast: a fixed 0.3 s window let
        # every shut-down kill find the process already gone). The shortest of five
        # runs, as it varies from run to run: with one run's, up to 18 of 25 missed.
        ends = [ref]
        for k in range(4):
            ends.append(Run(Path(tmp) / f"ref{k}"))
            assert ends[-1].finish() == 0, ends[-1].err
        shutdown_s = min(r.ended - max(t for t, topic in r.events if topic == "pass")
                         for r in ends)
        n_capture = len(ref.passes)
        state = Path(tmp) / "state"
        t_start = time.monotonic()
        # each kind in turn; a run that ended before its kill (it was quicker than the
        # draw) is audited like any other and its kind drawn again, so that ``--kills``
        # kills land (at most as many runs again)
        todo = [KINDS[i % len(KINDS)] for i in range(args.kills)]
        retries = args.kills
        while True:
            before = rows(state)
            last = not todo
            kind = "complete" if last else todo.pop(0)
            r = Run(state)
            if kind == "start-up":
                time.sleep(rng.uniform(0.0, first))
            elif kind == "in a pass":
                time.sleep(rng.uniform(first, run_s))
            elif kind == "in a commit":
                r.wait_passes(rng.randint(1, n_capture), 60.0)
                time.sleep(rng.uniform(0.0, 0.005))
            elif kind == "shut-down":
                r.wait_passes(n_capture, 60.0)
                time.sleep(rng.uniform(0.0, shutdown_s))
            killed = r.kill() if not last else False
            code = r.finish()
            if last and code != 0:
                faults["final run failed"] += 1
            if not last:
                if killed:
                    kinds[kind] += 1
                else:
                    missed[kind] += 1  # it had ended by itself first: draw again
                    if retries > 0:
                        retries -= 1
                        todo.insert(0, kind)
            audit = audit_log(state / "passes.sqlite") if (state / "passes.sqlite").exists() \
                else None
            for p in audit.problems if audit else []:
                faults[p.split(":")[0]] += 1
            after = rows(state)
            lost = [p for p in r.passes if after.get(p["pass"], (None,))[0] != p["truck"]
                    or abs((after[p["pass"]][1] or 0.0) - (p["payload_kg"] or 0.0)) > 0.1]
            faults["lost"] += len(lost)
            kept = {n: v for n, v in before.items()}
            if any(after.get(n) != v for n, v in kept.items()):
                faults["changed or lost from an earlier run"] += 1
            new = [v for n, v in after.items() if n not in before]
            starts = Counter(v[2] for v in new)
            faults["duplicated"] += sum(c - 1 for c in starts.values() if c > 1)
            m = re.search(r"next pass (\d+), truck (\d+) with (\d+) passes", r.err)
            if m and int(m.group(1)) != len(before) + 1:
                faults["restored the wrong next pass"] += 1
            if last:
                break
        elapsed = time.monotonic() - t_start
    print(f"kills: {sum(kinds.values())} in {elapsed:.0f} s ("
          + ", ".join(f"{k} {kinds[k]}" for k in KINDS) + "); the reference run: first "
          f"pass at {first:.2f} s, last event at {run_s:.2f} s; shut-down (the shortest of five) "
          f"{1e3 * shutdown_s:.0f} ms")
    if missed:
        print("  runs that ended before their kill (audited, and the kill drawn again): "
              + ", ".join(f"{k} {v}" for k, v in missed.items()))
    print(f"lost passes: {faults.pop('lost', 0)}, duplicated: {faults.pop('duplicated', 0)}")
    real = {k: v for k, v in faults.items() if v}
    print("other faults: " + (", ".join(f"{k} {v}" for k, v in real.items()) if real
                              else "none (integrity, numbering, open truck, restore)"))


if __name__ == "__main__":
    main()
