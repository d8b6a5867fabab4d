"""How far each pass's residuals are from their calibrated size, and whether that could
tell a pass weighed on a wrong crowd from a machine the model does not fully describe.

The statistic is the pass's own filter's mean normalised innovation squared per degree
of freedom (``PayloadRls.misfit``: about 1 when the model holds), as the engine records
it with each pass (``PassResult.misfit``, the pass message's ``misfit``). Three sets of
passes:

* ``--handle``: something lodged on the handle in the laser's beam, moving with it, from
  0.5-3 s after pass 1's dump to the end of the committed capture, 0.5-3 m off the
  target (the driver takes it after ``other_target_s``, inside pass 2, which is then not
  weighed; pass 3, on the offset crowd, was weighed until the thirty-third session and
  is now refused, the change of target having put the crowd in doubt); per seed: the
  offset, each pass's payload against the clean capture's, and its misfit;
* ``--machines N``: the realistic and the ideal simulated machines of
  ``bench/payload_accuracy.py`` (seeds 1..N, 60 passes each): the misfit's spread;
* ``--effects``: each simulated hidden effect alone at the bottom and the top of its
  typical range on ``bench/diagnose_matrix.py``'s machines (seeds 1, 2; 24 passes), the
  base model calibrated on the effect's own trials: the misfit's median and spread, and
  how many passes are above the daemon's level (the cab marks them), and how many the
  engine would not weigh with the crowd in doubt before every pass (``doubt_refusals``,
  the worst case of ``CrowdDoubt``; ``--machines`` prints it too); with ``--extend``
  (``run_extended``), identified four ways (the base model and the one extended by the
  effect's own term, each on the trials alone and on the trials plus verified passes)
  and judged on a fresh session: whether the marks go;
* ``--drift N``: a calibration that no longer fits its machine. Realistic machines
  (seeds 1000, 2000, ... N of them) calibrated on their trials, then one part of the
  machine changed (a dipper 5 % heavier, the hoist's or the crowd's pull per ampere 5 %
  weaker, friction half as much again, 15 % more inertia) and 12 passes weighed with the
  old calibration: the passes' median error, their misfit, and the empty dipper as the
  engine weighs it on each return (``EmptyCheck``).

    .venv/bin/python bench/pass_misfit.py [--handle] [--seeds 8] [--machines 18] [--effects]
        [--drift 2]
        [--effects --extend --only swing_centrifugal,sensor_time_skew,current_saturation]
"""

from __future__ import annotations

import argparse
import math
import random
import statistics
import tempfile
from pathlib import Path
from typing import Any

from shoveld.payload.misfit import MISFIT_RECENT, MISFIT_WARN


def doubt_refusals(misfits: list[float]) -> int:
    """The passes the engine would not weigh if the crowd were in doubt before every one
    of them (the worst case of ``CrowdDoubt``: a laser gap before each pass): each judged
    against the engine's ``doubt_limit`` of the median of the last passes weighed before
    it."""
    from collections import deque

    from shoveld.engine.loop import EngineConfig, doubt_limit

    cfg = EngineConfig()
    fits: deque[float] = deque(maxlen=MISFIT_RECENT)  # as the engine keeps them
    refused = 0
    for m in misfits:
        if not math.isfinite(m):
            continue
        if fits and m > doubt_limit(statistics.median(fits), cfg):
            refused += 1
        else:
            fits.append(m)
    return refused


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

    print(f"simulated machines 1..{n}, 60 passes each: misfit per pass; the empty dipper "
          "on each return, and the largest median of five returns (the warning's)")
    for kind in ("realistic", "ideal"):
        every: list[float] = []
        empty: list[float] = []
        medians: list[float] = []
        doubt = 0
        for seed in range(1, n + 1):
            machine = Machine.draw(seed) if kind == "realistic" else Machine.ideal()
            res = simulate_cycles(60, seed=10 * seed + 3, machine=machine,
                                  payload_range=(3000.0, 35000.0), truck_target_kg=None)
            cfg = EngineConfig(**pa.ENGINE)
            est = estimate_table(res.table, pa.calibrate(machine, seed, "output"), cfg)
            every.extend(p.misfit for p in est.passes)
            doubt += doubt_refusals([p.misfit for p in est.passes])
            empty.extend(e.payload_kg for e in est.empties)
            medians.extend(abs(e.median_kg) for e in est.empties[cfg.empty_returns - 1:])
        print(f"  {kind:10s} {len(every):5d} passes  {spread(every)}  not weighed with "
              f"the crowd in doubt before every pass: {doubt}")
        print(f"  {kind:10s} {len(empty):5d} returns  empty dipper {min(empty):+.0f} to "
              f"{max(empty):+.0f} kg, median of five at most {max(medians):.0f} kg",
              flush=True)


def pass_errors(est: Any, res: Any) -> list[float]:
    """Each weighed pass's error against the simulated truth."""
    from payload_accuracy import weighed

    return [got.payload_kg - tp.payload_kg for tp in res.passes
            if (got := weighed(est, tp)) is not None]


def run_effects(extend: bool, only: list[str]) -> None:
    from diagnose_matrix import simulate_session

    from shoveld.engine.offline import estimate_table
    from shoveld.identify.calibrate import Calibrator
    from shoveld.sim.effects import SIM_EFFECTS

    if extend:
        run_extended(only)
        return
    print("each hidden effect alone at the bottom and the top of its typical range, base "
          "model, seeds 1-2, 24 passes each: the misfit; the passes' error, median (RMS); "
          "the empty dipper on the returns, median (range)")
    for name in sorted(only or SIM_EFFECTS):
        for size in SIM_EFFECTS[name].typical_range:
            every: list[float] = []
            errs: list[float] = []
            empty: list[float] = []
            doubt = 0
            for seed in (1, 2):
                calib, ops = simulate_session({name: size}, seed, 24)
                params = Calibrator(method="output").fit(calib).params_
                assert params is not None  # fit sets it
                est = estimate_table(ops.table, params)
                every.extend(p.misfit for p in est.passes)
                doubt += doubt_refusals([p.misfit for p in est.passes])
                errs.extend(pass_errors(est, ops))
                empty.extend(e.payload_kg for e in est.empties)
            print(effect_line(name, size, "", every, errs, empty)
                  + f"  in doubt: {doubt}", flush=True)


def effect_line(name: str, size: float, label: str, every: list[float], errs: list[float],
                empty: list[float]) -> str:
    rms = math.sqrt(statistics.fmean(e * e for e in errs))
    return (f"  {name:24s} {size:8.3f} {label:13s} {spread(every)}  error "
            f"{statistics.median(errs):+6.0f} ({rms:5.0f}) kg  empty "
            f"{statistics.median(empty):+6.0f} ({min(empty):+.0f} to {max(empty):+.0f}) kg  "
            f"above {MISFIT_WARN:g}: {sum(m > MISFIT_WARN for m in every)}/{len(every)}")


def run_extended(only: list[str]) -> None:
    """The marks a missing term leaves (the cab's "?", the empty dipper's problem), and
    whether they go once the model has the term: each effect's machines identified four
    ways, judged on a fresh session of 24 passes on the same machine: the base model on
    the trials (what the daemon had); the model extended by the effect's own term on the
    trials alone (what ``shoveld calibrate --effects NAME`` did); the base model on the
    trials plus the first session's verified passes; and the extended model on the same
    (``shoveld calibrate --effects NAME --verified``, as after the diagnosis named it).
    The trials alone cannot identify a term only swinging excites: ``shoveld calibrate``
    now refuses it without verified passes."""
    from diagnose_matrix import simulate_session

    from shoveld.diagnose.fit import calibrate_with_verified
    from shoveld.engine.offline import estimate_table
    from shoveld.identify.calibrate import Calibrator
    from shoveld.model.effects import EFFECT_TERMS
    from shoveld.model.model import Model
    from shoveld.sim.effects import SIM_EFFECTS, make_effects
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_cycles

    print("each hidden effect at the bottom and the top of its typical range, seeds 1-2, "
          "judged on a fresh session of 24 passes: the misfit; the passes' error, median "
          "(RMS); the empty dipper on the returns; passes above the cab's level")
    for name in sorted(only or EFFECT_TERMS):
        for size in SIM_EFFECTS[name].typical_range:
            got: dict[str, tuple[list[float], list[float], list[float]]] = {}
            doubt: dict[str, int] = {}
            for seed in (1, 2):
                calib, ops = simulate_session({name: size}, seed, 24)
                held = simulate_cycles(24, 1000 * seed + 4, payload_range=(3000.0, 35000.0),
                                       truck_target_kg=None,
                                       effects=make_effects({name: size}, form="bench"),
                                       machine=Machine.draw(1000 * seed))
                fits = {
                    "base, trials": Calibrator(method="output").fit(calib).params_,
                    "+term, trials": Calibrator(model=Model.from_names([name]),
                                                method="output").fit(calib).params_,
                    "base, +passes": calibrate_with_verified(
                        Model.from_names([]), calib, [ops.table], method="output")[0].params_,
                    "+term, +passes": calibrate_with_verified(
                        Model.from_names([name]), calib, [ops.table],
                        method="output")[0].params_}
                for label, params in fits.items():
                    assert params is not None  # fit sets it
                    est = estimate_table(held.table, params)
                    every, errs, empty = got.setdefault(label, ([], [], []))
                    every.extend(p.misfit for p in est.passes)
                    errs.extend(pass_errors(est, held))
                    empty.extend(e.payload_kg for e in est.empties)
                    doubt[label] = doubt.get(label, 0) + doubt_refusals(
                        [p.misfit for p in est.passes])
            for label, (every, errs, empty) in got.items():
                print(effect_line(name, size, label, every, errs, empty)
                      + f"  in doubt: {doubt[label]}", flush=True)


DRIFTS: dict[str, dict[str, float]] = {
    "nothing changed": {}, "dipper +5 %": {"Md": 1.05}, "hoist pull -5 %": {"K_H": 0.95},
    "crowd pull -5 %": {"K_C": 0.95}, "handle friction x1.5": {"fc3": 1.5, "fv3": 1.5},
    "arm inertia +15 %": {"Izz": 1.15}}
"""Changes of the machine after its calibration, as factors on its plant's values."""


def run_drift(n: int) -> None:
    from dataclasses import replace

    from shoveld.engine.offline import estimate_table
    from shoveld.identify.calibrate import Calibrator
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_calibration, simulate_cycles

    print("the machine changed after its calibration, 12 passes weighed with the old one: "
          "median pass error, misfit median (range), the empty dipper on the returns")
    for seed in range(1000, 1000 * n + 1, 1000):
        m = Machine.draw(seed)
        trials = [simulate_calibration(kg, seed + k, machine=m).table
                  for k, kg in ((1, 0.0), (2, 8420.0))]
        params = Calibrator(method="output").fit(trials).params_
        assert params is not None  # fit sets it
        for name, change in DRIFTS.items():
            plant = replace(m.plant, **{k: getattr(m.plant, k) * f for k, f in change.items()})
            res = simulate_cycles(12, seed + 3, machine=replace(m, plant=plant),
                                  payload_range=(3000.0, 35000.0), truck_target_kg=None)
            est = estimate_table(res.table, params)
            errs = pass_errors(est, res)
            ms = [p.misfit for p in est.passes]
            empty = [e.payload_kg for e in est.empties]
            print(f"  machine {seed}  {name:22s} error {statistics.median(errs):+7.0f} kg  "
                  f"misfit {statistics.median(ms):5.2f} ({min(ms):.2f}-{max(ms):.2f})  "
                  f"empty dipper {statistics.median(empty):+6.0f} kg "
                  f"({min(empty):+.0f} to {max(empty):+.0f}, {len(empty)} returns)",
                  flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--handle", action="store_true")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--machines", type=int, default=0)
    ap.add_argument("--effects", action="store_true")
    ap.add_argument("--extend", action="store_true",
                    help="with --effects: also weigh with the model extended by each "
                         "effect's own term")
    ap.add_argument("--only", default="", metavar="NAME,...",
                    help="with --effects: these effects only")
    ap.add_argument("--drift", type=int, default=0, metavar="N")
    args = ap.parse_args()
    if not (args.handle or args.machines or args.effects or args.drift):
        ap.error("say what to measure: --handle, --machines N, --effects or --drift N")
    import logging

    logging.basicConfig(level=logging.ERROR)
    if args.handle:
        run_handle(args.seeds)
    if args.machines:
        run_machines(args.machines)
    if args.effects:
        run_effects(args.extend, [n for n in args.only.split(",") if n])
    if args.drift:
        run_drift(args.drift)


if __name__ == "__main__":
    main()
