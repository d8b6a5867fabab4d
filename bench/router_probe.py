"""What the router probe buys and what it costs (issue 12): how soon a session sees its
router hung, with the probe and with the lease alone, and the probe's CPU.

A site router (a Zenoh router process on loopback, the site's 2 s lease, its admin space
open as ``shoveld pki router-config`` writes it) is stopped with SIGSTOP ``--hangs``
times at a random moment and resumed; each time it prints how long a client session took
to see it gone: with ``shoveld.daemon.router_probe`` (the router silent for ``SILENT_S``;
on a router that answers its question, then on one whose admin space is closed, which a
client judges by its questions' ends) and with the lease alone (the router no longer
among the session's routers: what a session sees without the probe). Then the CPU of a
client session connected to an idle router, in blocks of ``--seconds`` alternating
without and with the probe, as % of one core (median and range of the blocks'
differences).

    .venv/bin/python bench/router_probe.py [--hangs 10] [--blocks 4] [--seconds 10]
"""

from __future__ import annotations

import argparse
import random
import statistics
import time
from typing import Any

from hil_fixtures.net import free_port
from hil_fixtures.router import Router
from shoveld.daemon.publisher import wait_until, zenoh_config
from shoveld.daemon.router_probe import PERIOD_S, SILENT_S, RouterProbe
from shoveld.security.acl import ROUTER_LEASE_S

STEP_S = 0.002
"""How often the bench looks (the seconds it prints are to this)."""


def hangs(admin: bool, by_probe: bool, n: int, rng: random.Random) -> list[float]:
    """Seconds from each SIGSTOP to a client session seeing its router gone: by the probe
    (``by_probe``) or by the router leaving the session's routers (its lease)."""
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    out: list[float] = []
    with Router(endpoint, admin=admin) as router:
        session: Any = zenoh.open(zenoh_config("client", (), [endpoint]))
        probe = RouterProbe(session).start()

        def routers() -> int:
            return len(list(session.info.routers_zid()))

        def gone() -> bool:
            return probe.silent() if by_probe else routers() == 0

        try:
            for _ in range(n):
                if not wait_until(lambda: routers() == 1 and (probe.judged() or not by_probe),
                                  20.0, STEP_S):
                    raise RuntimeError("the router was not reached again")
                time.sleep(rng.uniform(1.0, 1.0 + PERIOD_S))  # any moment between questions
                router.hang()
                t0 = time.monotonic()
                seen = wait_until(gone, 10.0, STEP_S)
                out.append(time.monotonic() - t0 if seen else float("nan"))
                router.resume()
        finally:
            probe.close()
            session.close()
    return out


def cpu(blocks: int, seconds: float) -> list[float]:
    """% of one core the probe adds to a client session on an idle router, per pair of
    blocks (without, then with)."""
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    diffs: list[float] = []
    with Router(endpoint):
        session: Any = zenoh.open(zenoh_config("client", (), [endpoint]))
        try:
            wait_until(lambda: len(list(session.info.routers_zid())) == 1, 10.0, STEP_S)
            for _ in range(blocks):
                pair = []
                for on in (False, True):
                    probe = RouterProbe(session).start() if on else None
                    c0, t0 = time.process_time(), time.monotonic()
                    time.sleep(seconds)
                    pair.append((time.process_time() - c0) / (time.monotonic() - t0))
                    if probe is not None:
                        probe.close()
                diffs.append(100 * (pair[1] - pair[0]))
        finally:
            session.close()
    return diffs


def _line(xs: list[float], unit: str, digits: int = 2) -> str:
    return (f"median {statistics.median(xs):.{digits}f} {unit}, range "
            f"{min(xs):.{digits}f}-{max(xs):.{digits}f} {unit} over {len(xs)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hangs", type=int, default=10)
    ap.add_argument("--blocks", type=int, default=4)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    print(f"router probe: a question every {PERIOD_S:g} s, gone after {SILENT_S:g} s "
          f"unanswered; the router's lease {ROUTER_LEASE_S:g} s")
    print("hung router seen by the probe:     " + _line(hangs(True, True, a.hangs, rng), "s"),
          flush=True)
    print("  its admin space closed:          " + _line(hangs(False, True, a.hangs, rng), "s"),
          flush=True)
    print("hung router seen by its lease:     " + _line(hangs(False, False, a.hangs, rng),
                                                        "s"), flush=True)
    print("CPU the probe adds to a session:   " + _line(cpu(a.blocks, a.seconds),
                                                        "% of a core", 3))


if __name__ == "__main__":
    main()
