"""Killed at any moment, the daemon comes back with every finished pass and its truck.

Two tests: the whole daemon (``shoveld replay --fast`` on the committed capture, with
its pass log in a state directory kept across runs) killed with SIGKILL at random
moments and restarted; and a writer hammering the pass log killed mid-write.
"""

from __future__ import annotations

import os
import random
import re
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

from shoveld.daemon.persist import PassLog, audit_log, db_path

from .conftest import CAPTURE, PARAMS, free_port

KILLS = 12
WRITER_KILLS = 20


def check_log(state: Path) -> tuple[list[int], int | None, list[int]]:
    """Integrity, contiguous unique pass ids; return (ids, open truck, its passes)."""
    a = audit_log(db_path(state))
    assert not a.problems, a.problems
    return a.passes, a.open_truck, a.open_truck_passes


def test_daemon_killed_repeatedly_keeps_every_pass(tmp_path: Path) -> None:
    rng = random.Random(4)
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[shovel]\nid = "k"\nparams = "{PARAMS}"\n\n[truck]\ntarget_kg = 62000.0\n')
    state = tmp_path / "state"
    cmd = [sys.executable, "-m", "shoveld", "-v", "replay", str(CAPTURE), "--fast",
           "--config", str(cfg), "--state-dir", str(state), "--zenoh-wait", "0"]
    # Kill moments are drawn within a complete run's duration, measured first on its own
    # state directory, so a faster replay still dies mid-run rather than after the end.
    t0 = time.monotonic()
    timing = [str(tmp_path / "timing") if a == str(state) else a for a in cmd]
    subprocess.run([*timing, "--listen", f"tcp/127.0.0.1:{free_port()}"],
                   capture_output=True, check=True, timeout=120)
    run_s = time.monotonic() - t0
    before: tuple[list[int], int | None, list[int]] = ([], None, [])
    killed = 0
    for i in range(KILLS + 1):
        last = i == KILLS
        port = free_port()
        proc = subprocess.Popen(cmd + ["--listen", f"tcp/127.0.0.1:{port}"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if last:
            out, err = proc.communicate(timeout=120)
            assert proc.returncode == 0, err
        else:
            time.sleep(rng.uniform(0.1, 0.7) * run_s)
            proc.send_signal(signal.SIGKILL)
            out, err = proc.communicate(timeout=30)
            # On a busy machine a run may still end before its kill: a complete run.
            assert proc.returncode in (-signal.SIGKILL, 0), err
            killed += proc.returncode == -signal.SIGKILL
        m = re.search(r"next pass (\d+), truck (\d+) with (\d+) passes", err)
        if m:  # it got as far as restoring: from exactly what the log held
            ids, cur, cur_passes = before
            assert int(m.group(1)) == len(ids) + 1
            if cur is not None:
                assert (int(m.group(2)), int(m.group(3))) == (cur, len(cur_passes))
        if (state / "passes.sqlite").exists():
            after = check_log(state)
            assert after[0][:len(before[0])] == before[0]  # nothing finished was lost
            before = after
    assert killed >= KILLS * 2 // 3, f"only {killed} of {KILLS} runs were killed mid-run"
    ids, cur, cur_passes = before
    assert len(ids) >= 3  # the final complete run alone adds the capture's three passes
    assert cur is None  # the complete run closed its last truck


WRITER = """
import sys
from shoveld.daemon.persist import PassLog
log = PassLog(sys.argv[1], "w")
r = log.restore()
n, truck, in_truck = r.next_pass, r.truck, len(r.truck_passes)
while True:  # like the engine: continue the restored truck, close it after 4 passes
    p = {"pass": n, "truck": truck, "start_s": n, "end_s": n + 1.0,
         "payload_kg": 30000.0 + n, "std_kg": 100.0, "samples": 300, "valid": True,
         "reason": ""}
    log.write_pass(p, 1.79e9 + n, 1.79e9 + n + 1, 62000.0)
    in_truck += 1
    if in_truck == 4:
        log.close_truck(truck, 62000.0, 1.79e9 + n + 2)
        truck, in_truck = truck + 1, 0
    sys.stdout.write(f"{n}\\n")
    sys.stdout.flush()
    n += 1
"""


def test_pass_log_killed_mid_write_stays_consistent(tmp_path: Path) -> None:
    rng = random.Random(7)
    path = db_path(tmp_path)
    committed = 0
    for _ in range(WRITER_KILLS):
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)],
                                stdout=subprocess.PIPE, text=True,
                                env={**os.environ, "PYTHONUNBUFFERED": "1"})
        time.sleep(rng.uniform(0.15, 0.4))
        proc.send_signal(signal.SIGKILL)
        out, _ = proc.communicate(timeout=10)
        reported = [int(x) for x in out.split()]
        ids, cur, cur_passes = check_log(tmp_path)
        # every pass the writer saw committed is there; at most the one in flight more
        if reported:
            assert reported[-1] <= len(ids) <= reported[-1] + 1
        assert len(ids) >= committed
        committed = len(ids)
        r = PassLog(path, "check").restore()
        assert r.next_pass == len(ids) + 1
        con = sqlite3.connect(path)
        max_truck = con.execute("SELECT max(truck) FROM trucks").fetchone()[0]
        con.close()
        assert r.truck == (cur if cur is not None else max_truck + 1)
        assert [p["pass"] for p in r.truck_passes] == cur_passes
    assert committed > 20
