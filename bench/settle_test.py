"""The settle time's test against bank contact that lingers: RMS/CRB of the payload with
the settle time never used, tested (the default), and always used.

The simulator's bank force fades to nothing before the phase machine sees the dipper
leave the bank, so on its own data the settle time is always clean. A real bank can hold
on longer (teeth dragging out of the material). Here the hoist pulls harder after each
dig's true end by ``A exp(-t / tau)`` amps (split over the two motors; the joints move
as before), and each variant's payloads are compared with the truth
(docs/engine.md, "The settle time, tested").

    .venv/bin/python bench/settle_test.py [--machines 6] [--passes 40] [--jobs 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import payload_accuracy as pa  # noqa: E402  (bench/ is not a package)

TAILS = ((0.0, 0.3), (50.0, 0.3), (150.0, 0.3), (150.0, 0.6), (400.0, 0.3))
"""(A amps, tau seconds) of the extra hoist current after each dig's end."""
VARIANTS = ("never", "tested", "always")


def configs() -> dict[str, Any]:
    from shoveld.engine.loop import EngineConfig

    return {"never": EngineConfig(settle_test_z=0.0), "tested": EngineConfig(),
            "always": EngineConfig(settle_s=0.0)}


def one_machine(job: tuple[int, int]) -> dict[tuple[float, float, str], list[tuple[float, float]]]:
    from shoveld.signals.table import SignalsTable
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_cycles

    seed, n = job
    machine = Machine.draw(seed)
    params = pa.calibrate(machine, seed, "output")
    res = simulate_cycles(n, seed=10 * seed + 3, machine=machine,
                          payload_range=(3000.0, 35000.0), truck_target_kg=None)
    t = res.table.time
    out: dict[tuple[float, float, str], list[tuple[float, float]]] = {}
    for amp, tau in TAILS:
        cols = {k: v.copy() for k, v in res.table.columns.items()}
        for tp in res.passes:
            after = t >= tp.phases["dig"][1]
            extra = amp * np.exp(-(t[after] - tp.phases["dig"][1]) / tau)
            cols["hoist1_a"][after] += extra / 2
            cols["hoist2_a"][after] += extra / 2
        table = SignalsTable.from_arrays(meta=dict(res.table.meta), **cols)
        for name, cfg in configs().items():
            out[(amp, tau, name)] = [(r["err"], r["crb"])
                                     for r in pa.passes(params, res, table, cfg) if r["valid"]]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--machines", type=int, default=6)
    ap.add_argument("--passes", type=int, default=40, help="passes per machine")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows: dict[tuple[float, float, str], list[tuple[float, float]]] = {}
    with ProcessPoolExecutor(args.jobs) as ex:
        for out in ex.map(one_machine, [(s, args.passes)
                                        for s in range(1, args.machines + 1)]):
            for k, r in out.items():
                rows.setdefault(k, []).extend(r)
    print(f"payload error over {args.machines} realistic machines x {args.passes} passes, "
          "with an extra hoist current A exp(-t/tau) after each dig's end; "
          "RMS/CRB (mean error kg)")
    print(f"  {'A':>5s} {'tau':>5s}  " + "  ".join(f"{v:>16s}" for v in VARIANTS))
    for amp, tau in TAILS:
        cells = []
        for v in VARIANTS:
            e = np.array(rows[(amp, tau, v)])
            rms = float(np.sqrt(np.mean(e[:, 0] ** 2)) / np.mean(e[:, 1]))
            cells.append(f"{rms:6.2f} ({e[:, 0].mean():+5.0f} kg)")
        print(f"  {amp:5.0f} {tau:5.1f}  " + "  ".join(f"{c:>16s}" for c in cells))
    print(f"\n({time.perf_counter() - t0:.0f} s wall, {args.jobs} workers)")


if __name__ == "__main__":
    main()
