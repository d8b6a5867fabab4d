"""How far each pass's residuals are from their calibrated size, and whether that could
tell a pass weighed on a wrong crowd from a machine the model does not fully describe.

The statistic is the pass's own filter's mean normalised innovation squared per degree
of freedom (``PayloadRls.misfit``: about 1 when the model holds), as the engine records
it with each pass (``PassResult.misfit``, the pass message's ``misfit``). Three sets of
passes:

* ``--handle``: something lodged on the handle in the laser's beam, moving with it, from
  0.5-3 s after pass 1's dump to the end of the committed capture, 0.5-3 m off the
  target (the driver takes it after ``other_target_s``, inside pass 2, which is then not
  weighed; pass 3 is weighed on the offset crowd); per seed: the offset, each pass's
  payload against the clean capture's, and its misfit;
* ``--machines N``: the realistic and the ideal simulated machines of
  ``bench/payload_accuracy.py`` (seeds 1..N, 60 passes each): the misfit's spread;
* ``--effects``: each simulated hidden effect alone at the bottom and the top of its
  typical range on ``bench/diagnose_matrix.py``'s machines (seeds 1, 2; 24 passes), the
  base model calibrated on the effect's own trials: the misfit's median and spread.

    .venv/bin/python bench/pass_misfit.py [--handle] [--seeds 8] [--machines 18] [--effects]
"""

from __future__ import annotations

import argparse
import random
import statistics
import tempfile
from pathlib import Path


def spread(xs: list[float]) -> str:
    return (f"median {statistics.median(xs):7.2f}  min {min(xs):7.2f}  max {max(xs):7.2f}"
            if xs else "no pass")


def run_handle(seeds: int) -> None:
    import laser_strays as ls

    base = ls.replay(ls.CAPTURE)
    clean = dict(base["passes"])
    print("something on the handle after pass 1's dump, to the end (pass: kg off the clean "
          "capture's, misfit)")
    print(f"  clean capture: misfits {' '.join(f'{m:.2f}' for m in base['misfits'].values())}")
    end1, end = base["spans"][0][2], base["spans"][-1][2]
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(1, seeds + 1):
            rng = random.Random(seed)
            t0 = end1 + rng.uniform(0.5, 3.0)
            off = rng.choice((-1, 1)) * rng.randint(500, 3000)
            cap = ls.stray_capture(Path(tmp) / f"h{seed}", 0.0, seed, True,
                                   blocks=[(t0, end + 100.0, off)])
            r = ls.replay(cap)
            cells = []
            for no, kg in r["passes"]:
                m = r["misfits"][no]
                what = "not weighed" if kg is None else f"{kg - clean[no]:+9.0f} kg"
                fit = "   none" if m is None else f"{m:7.2f}"  # no valid sample
                cells.append(f"pass {no}: {what}, misfit {fit}")
            print(f"  seed {seed:2d}, {off:+5d} mm: " + "; ".join(cells))


def run_machines(n: int) -> None:
    import payload_accuracy as pa

    from shoveld.engine.loop import EngineConfig
    from shoveld.engine.offline import estimate_table
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_cycles

    print(f"simulated machines 1..{n}, 60 passes each: misfit per pass")
    for kind in ("realistic", "ideal"):
        every: list[float] = []
        for seed in range(1, n + 1):
            machine = Machine.draw(seed) if kind == "realistic" else Machine.ideal()
            res = simulate_cycles(60, seed=10 * seed + 3, machine=machine,
                                  payload_range=(3000.0, 35000.0), truck_target_kg=None)
            est = estimate_table(res.table, pa.calibrate(machine, seed, "output"),
                                 EngineConfig(**pa.ENGINE))
            every.extend(p.misfit for p in est.passes)
        print(f"  {kind:10s} {len(every):5d} passes  {spread(every)}")


def run_effects() -> None:
    from diagnose_matrix import simulate

    from shoveld.engine.offline import estimate_table
    from shoveld.identify.calibrate import Calibrator
    from shoveld.sim.effects import SIM_EFFECTS

    print("each hidden effect alone at the bottom and the top of its typical range, base "
          "model, seeds 1-2, 24 passes each")
    for name in sorted(SIM_EFFECTS):
        for size in SIM_EFFECTS[name].typical_range:
            every: list[float] = []
            for seed in (1, 2):
                calib, measured, _ = simulate({name: size}, seed, 24)
                est = estimate_table(measured[0],
                                     Calibrator(method="output").fit(calib).params_)
                every.extend(p.misfit for p in est.passes)
            print(f"  {name:24s} {size:8.3f}  {spread(every)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--handle", action="store_true")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--machines", type=int, default=0)
    ap.add_argument("--effects", action="store_true")
    args = ap.parse_args()
    if not (args.handle or args.machines or args.effects):
        ap.error("say what to measure: --handle, --machines N or --effects")
    import logging

    logging.basicConfig(level=logging.ERROR)
    if args.handle:
        run_handle(args.seeds)
    if args.machines:
        run_machines(args.machines)
    if args.effects:
        run_effects()


if __name__ == "__main__":
    main()
