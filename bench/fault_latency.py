"""How soon health names a sensor or network fault made during a pass, on the live daemon
(issue 12).

Each drill (``hil_fixtures/fault_drill.py``) runs the daemon on the virtual shovel's
emulators at real time, connected to a site router, and makes each fault while a pass is
under way: the MTi unplugged and silent, the laser unplugged, silent and babbling, a
Modbus module powered off, silent, babbling and answering after its timeout, and the
site's router gone (its process ended) and hung (stopped with its sockets open). It
prints, per fault, the time from the fault to the arrival of the first health message
naming its device (at a Zenoh subscriber, as a cab), in seconds and against the bound
the issue sets (one health period after the fault can be seen: the device's
``max_age_s``; a hung router, the router probe's ``SILENT_S``), the live estimates
published as numbers while the fault's inputs were invalid (goal 0), the loop's rate and
overruns, and the passes published against those in the pass log (goal: none lost).

Usage: ``.venv/bin/python bench/fault_latency.py [--runs 3] [--health-period 1.0]
[--adc tcp|rtu]`` (``rtu``: the Modbus modules over RTU on pseudo-terminals)
(about 100 s a run, and the table of cycles first)
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PARAMS = ROOT / "hil_fixtures" / "captures" / "daemon-e2e" / "params.toml"


def main() -> None:
    from hil_fixtures.fault_drill import cycles, run_drill, summary
    from shoveld.daemon.router_probe import SILENT_S

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--health-period", type=float, default=1.0)
    ap.add_argument("--passes", type=int, default=8, help="dig cycles played (8)")
    ap.add_argument("--adc", choices=("tcp", "rtu"), default="tcp",
                    help="the Modbus modules' transport (tcp; rtu over pseudo-terminals)")
    a = ap.parse_args()
    table = cycles(a.passes)
    drills = []
    for i in range(a.runs):
        with tempfile.TemporaryDirectory() as tmp:
            d = run_drill(table, PARAMS, Path(tmp), health_period_s=a.health_period,
                          seed=i + 1, adc_transport=a.adc)
        drills.append(d)
        worst = max((o.latency_s for o in d.outcomes if o.latency_s is not None),
                    default=float("nan"))
        print(f"drill {i + 1}: {len(d.outcomes)} faults, largest latency {worst:.2f} s; "
              f"loop {d.rate_hz:.2f} Hz over {d.seconds:.0f} s, {d.overruns} overruns; "
              f"passes published {d.passes_published}, in the pass log {d.passes_logged}"
              + "".join(f"\n  note: {n}" for n in d.notes), flush=True)
    bound = drills[0].max_age_s + a.health_period
    print(f"per fault over {len(drills)} drills (bound: max_age_s {drills[0].max_age_s:g} s + "
          f"one health period {a.health_period:g} s = {bound:g} s; a hung router is seen "
          f"when it has not answered the probe for {SILENT_S:g} s, so "
          f"{SILENT_S + a.health_period:g} s):")
    for line in summary(drills):
        print("  " + line)


if __name__ == "__main__":
    main()
