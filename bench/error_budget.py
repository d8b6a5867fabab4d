"""Where the remaining error comes from: the realism switched off one piece at a time.

Two tables, on realistic simulated machines (``shoveld.sim.machine``):

* **payload**: per-pass error against the Cramer-Rao bound of the current noise, with
  the identified parameters, with the machine's true parameters (what identification
  costs), and with the true parameters on a machine whose angle sensors, or field
  channel, are noise-free (what the kinematics cost);
* **parameters** (``--ablate``): the bias of each identified parameter (mean error over
  mean standard error) and its coverage within 2 standard errors, with all the realism
  and with one piece removed at a time. This is how the friction's bias was traced to
  the held poses (docs/engine.md, "Held poses are still").

    .venv/bin/python bench/error_budget.py [--machines 6] [--passes 60]
                                           [--ablate 20] [--jobs 2]
                                           [--window S --polyorder N] [--no-angle-noise]
                                           [--settle-test-z Z]

``--window``/``--polyorder``/``--[no-]angle-noise``: the identification's options, and
``--settle-test-z`` the engine's settle test, as in ``bench/payload_accuracy.py``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from shoveld.model.terms import knot_group

sys.path.insert(0, str(Path(__file__).resolve().parent))
import payload_accuracy as pa  # noqa: E402  (bench/ is not a package)

R = dataclasses.replace
ARMATURE = ("hoist1", "hoist2", "crowd")


def variant(machine: Any, name: str) -> Any:
    """The machine with one piece of its realism removed."""
    s = machine.sensors
    if name == "all realism":
        return machine
    if name == "noise-free angles":
        s = R(s, handle_deg=0.0, crowd_m=0.0, swing_deg=0.0, boom_deg=0.0)
    elif name == "noise-free angles, no drift":
        s = R(s, handle_deg=0.0, crowd_m=0.0, swing_deg=0.0, boom_deg=0.0,
              handle_drift_deg=0.0)
    elif name == "no handle drift":
        s = R(s, handle_drift_deg=0.0)
    elif name == "noise-free handle angle":
        s = R(s, handle_deg=0.0)
    elif name == "noise-free crowd extension":
        s = R(s, crowd_m=0.0)
    elif name == "noise-free field channel":
        s = R(s, hoist_field=R(s.hoist_field, noise_a=0.0, bits=24))
    elif name == "noise-free currents":
        s = R(s, **{c: R(getattr(s, c), noise_a=0.0, noise_rel=0.0, bits=24) for c in ARMATURE})
    elif name == "no drift or split wander":
        s = R(s, handle_drift_deg=0.0, split_wander=0.0)
    elif name == "no offsets or gain errors":
        s = R(s, **{c: R(getattr(s, c), offset_a=0.0, gain=0.0)
                    for c in (*ARMATURE, "hoist_field")})
    elif name == "no field weakening":
        return R(machine, drive=None)
    else:
        raise KeyError(name)
    return R(machine, sensors=s)


PAYLOAD_ROWS = (("identified parameters", "all realism", False),
                ("true parameters", "all realism", True),
                ("true parameters, noise-free field channel", "noise-free field channel", True),
                ("true parameters, no handle drift", "no handle drift", True),
                ("true parameters, noise-free angles", "noise-free angles", True),
                ("true parameters, noise-free angles, no drift", "noise-free angles, no drift",
                 True))

ABLATIONS = ("all realism", "noise-free angles", "noise-free handle angle",
             "noise-free crowd extension", "noise-free currents", "noise-free field channel",
             "no drift or split wander", "no offsets or gain errors")


def payload_job(job: dict[str, Any]) -> dict[str, Any]:
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_cycles

    seed = job["seed"]
    machine = Machine.draw(seed)
    p = pa.calibrate(machine, seed, "output")
    truth = machine.truth_for(p)
    p_true = dataclasses.replace(p, values=np.array([truth[n] for n in p.names]))
    out: dict[str, Any] = {}
    for label, name, oracle in PAYLOAD_ROWS:
        res = simulate_cycles(job["passes"], seed=10 * seed + 3,
                              machine=variant(machine, name),
                              payload_range=(3000.0, 35000.0), truck_target_kg=None)
        rows = [r for r in pa.passes(p_true if oracle else p, res) if r["valid"]]
        out[label] = [(r["err"], r["crb"]) for r in rows]
    return out


def ablation_job(job: tuple[str, int]) -> tuple[str, dict[str, tuple[float, float, float]]]:
    from shoveld.sim.machine import Machine

    name, seed = job
    machine = variant(Machine.draw(seed), name)
    p = pa.calibrate(machine, seed, "output")
    truth = machine.truth_for(p)
    return name, {knot_group(n): (float(v) - truth[n], float(se), truth[n])
                  for n, v, se in zip(p.names, p.values, p.stderr, strict=True)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--machines", type=int, default=6)
    ap.add_argument("--passes", type=int, default=60, help="passes per machine")
    ap.add_argument("--ablate", type=int, default=20,
                    help="machines per row of the parameter table (0: skip it)")
    ap.add_argument("--jobs", type=int, default=2)
    pa.add_identification_args(ap)
    args = ap.parse_args()
    options = pa.identification_options(args)
    engine = pa.engine_options(args)
    if options or engine:
        print(f"options: {options | engine}")
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs, initializer=pa._init,
                             initargs=(options, engine)) as ex:
        res = list(ex.map(payload_job, [{"seed": s, "passes": args.passes}
                                        for s in range(1, args.machines + 1)]))
        abl = list(ex.map(ablation_job, [(n, s) for n in ABLATIONS
                                         for s in range(101, 101 + args.ablate)]))
    print(f"payload error over {args.machines} realistic machines x {args.passes} passes of "
          "3-35 t; CRB = Cramer-Rao bound of the current noise")
    for label, _, _ in PAYLOAD_ROWS:
        a = np.array([r for m in res for r in m[label]])
        e, crb = a[:, 0], a[:, 1]
        rms = float(np.sqrt(np.mean(e**2)))
        print(f"  {label:46s} n={len(e):4d}  mean {e.mean():+5.0f} kg  RMS {rms:4.0f} kg  "
              f"RMS/CRB {rms / np.mean(crb):4.2f}")
    if abl:
        print(f"\nidentified parameters over {args.ablate} machines per row: bias (mean error "
              "/ mean std err), within 2 std err")
        names = list(dict.fromkeys(n for _, d in abl for n in d))
        print("  " + " " * 27 + "".join(f"{n:>12s}" for n in names))
        for row in ABLATIONS:
            rs = [d for name, d in abl if name == row]
            cells = []
            for n in names:  # (a field knot: the machines that have it)
                e = np.array([d[n][0] for d in rs if n in d])
                se = np.array([d[n][1] for d in rs if n in d])
                cells.append(f"{e.mean() / se.mean():+5.2f} {np.mean(np.abs(e) <= 2 * se):4.0%}")
            print(f"  {row:27s}" + "".join(f"{c:>12s}" for c in cells))
    print(f"\n({time.perf_counter() - t0:.0f} s wall, {args.jobs} workers)")


if __name__ == "__main__":
    main()
