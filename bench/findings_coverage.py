"""Do the physical values the diagnosis reports cover the simulated truth?

``shoveld diagnose`` reports, for a named cause, values a field engineer can check on
the machine, each with a standard deviation (``ExtensionTerm.findings``: the delta
method through the fitted parameters' covariance). For the causes whose simulated
effect has a value of the same meaning, each case draws a realistic machine, hides the
effect at a magnitude from its typical range (bench form), identifies the base model
plus the effect's term as the diagnosis's final model is identified (the trials, and
the verified passes where the term needs them) and compares each reported value with
the truth:

* ``hoist_rope_mass``: the ropes' mass per metre;
* ``ground_slope``: the boom's tilt per degree of deck pitch, 1 on a slope;
* ``payload_cog_offset``: the load's centre of gravity in front of and below the bail
  (the bench form is a heap in the bowl: the truth is its centre of mass);
* ``swing_centrifugal``: the swing axis to the shipper shaft (the simulated arm turns
  in 3D at that radius);
* ``load_dependent_friction``: the shipper shaft's friction per tonne of load (the
  simulated coefficient on a 0.5 m bearing radius; the saddle block's depends on the
  handle's angle in the simulator, so it has no single truth);
* ``boom_suspension_spring``: the boom point's drop at the term's reference hoist current
  (500 A as measured) and pose (the handle level, the bail 8.5 m out, where the
  simulator's magnitude is defined): the simulated drop at the rope pull that current
  gives at the nominal field. The simulated drop per newton follows the moment of both
  rope pulls about the boom foot, the term's the bail rope's alone.

Prints per value the error (mean +- sd), the reported standard deviation (median), how
often the truth lies within one and two of them and the RMS of error over standard
deviation (1 when the figure is honest). The time skew's delays have their own bench
(``bench/delay_uncertainty.py``).

``--machine`` swaps parts of the machine for the thesis's (to take a bias apart) and
``--magnitude`` fixes the effect's size (a bias that grows with it is a missing term).

Usage: ``.venv/bin/python bench/findings_coverage.py [--seeds 10] [--jobs 2]
[--effects NAME,...] [--machine drawn] [--magnitude X] [--json out.jsonl]``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from _run import model_error, run_cases  # noqa: E402

EFFECTS = ("hoist_rope_mass", "ground_slope", "payload_cog_offset", "swing_centrifugal",
           "load_dependent_friction", "boom_suspension_spring")


def truths(name: str, magnitude: float, machine: Any, params: Any) -> dict[str, float]:
    """The reported values' true ones, by the start of their wording (``machine``: the
    simulated :class:`~shoveld.sim.machine.Machine`, ``params`` the fit, for values in
    the units of its K_H: the pull per measured ampere at its nominal field)."""
    from shoveld.sim.effects import (
        LoadDependentFrictionEffect,
        PayloadCogOffsetEffect,
        make_effects,
    )

    if name == "hoist_rope_mass":
        return {"hoist rope mass": magnitude}
    if name == "ground_slope":
        return {"boom tilt per degree": 1.0}
    if name == "payload_cog_offset":
        (e,) = make_effects({name: magnitude}, form="bench")
        assert isinstance(e, PayloadCogOffsetEffect)
        heap = np.array(e._heap())  # (share, along the handle, across it, up positive)
        return {"load centre of gravity in front": float(heap[:, 0] @ heap[:, 1]),
                "load centre of gravity below": float(-(heap[:, 0] @ heap[:, 2]))}
    if name == "swing_centrifugal":
        return {"swing axis to shipper shaft": magnitude}
    if name == "load_dependent_friction":
        (e,) = make_effects({name: magnitude}, form="bench")
        assert isinstance(e, LoadDependentFrictionEffect)
        return {"shipper-shaft friction per tonne": 1000.0 * magnitude * e.shaft_radius_m * 9.81}
    if name == "boom_suspension_spring":
        from shoveld.model.effects import BoomSuspensionSpring
        from shoveld.sim.effects import BoomSuspensionSpringEffect

        # the pull of the term's reference current at the fit's nominal field
        ref = BoomSuspensionSpring.defaults["ref_a"]
        return {"boom point drop": BoomSuspensionSpringEffect(magnitude).drop_deg_at(
            machine.k_h_nominal(params) * ref)}
    raise ValueError(f"no truth for {name!r}")


MACHINES = ("drawn", "thesis", "thesis-lowering-nominal", "drawn-thesis-drive")
"""A machine drawn per case; the thesis's; the thesis's with its hoist field nominal when
lowering (no stroke of the trials excluded as weak-field); a drawn one with the
thesis's two-level drive (every lowering stroke excluded)."""


def _machine(kind: str, drawn: Any, thesis: Any) -> Any:
    from dataclasses import replace

    if kind == "drawn":
        return drawn
    if kind == "thesis":
        return thesis
    if kind == "thesis-lowering-nominal":
        return replace(thesis, plant=replace(
            thesis.plant, hoist_field_lowering_a=thesis.plant.hoist_field_hoisting_a))
    if kind == "drawn-thesis-drive":
        return replace(drawn, drive=thesis.drive)
    raise ValueError(f"unknown machine {kind!r}; expected one of {MACHINES}")


def one(job: dict[str, Any]) -> dict[str, Any]:
    """Simulate one machine with the effect and identify the base model plus its term."""
    from shoveld.diagnose.data import DataSet
    from shoveld.diagnose.fit import fit, needs_operation
    from shoveld.diagnose.report import findings
    from shoveld.model.model import Model
    from shoveld.sim.effects import make_effects
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_calibration, simulate_cycles

    name, mag, seed = job["effect"], job["magnitude"], job["seed"]
    base = 1000 * seed
    machine = _machine(job.get("machine", "drawn"), Machine.draw(base), Machine.ideal())

    def fx() -> list[Any]:
        return make_effects({name: mag}, form="bench")

    calib = [simulate_calibration(load, base + i + 1, effects=fx(), machine=machine).table
             for i, load in enumerate((0.0, 8420.0))]
    ops = simulate_cycles(24, base + 3, payload_range=(3000.0, 35000.0), truck_target_kg=None,
                          verified_fraction=0.5, effects=fx(), machine=machine)
    ds = DataSet(calib, [ops.table])
    t0 = time.perf_counter()
    train = ({p.index for p in ds.passes if p.verified}
             if needs_operation(Model.from_names([name]), ds) else None)
    params = fit(ds, [name], {}, train)
    true = truths(name, mag, machine, params)
    out = []
    for f in findings(params, [name]).get(name, []):
        key = next((k for k in true if f["what"].startswith(k)), None)
        if key is not None:
            out.append({"what": key, "value": f["value"], "std": f["std"],
                        "std_fit": f["std_fit"], "truth": true[key]})
    return {**job, "findings": out, "fit_s": time.perf_counter() - t0,
            "with_passes": train is not None}


def summary(results: list[dict[str, Any]]) -> None:
    rows: dict[str, list[tuple[float, float, float]]] = {}
    for r in results:
        for f in r["findings"]:
            rows.setdefault(f"{r['effect']}: {f['what']}", []).append(
                (f["value"] - f["truth"], f["std"], f.get("std_fit", f["std"])))
    print("value: error mean +- sd | reported std, median | truth within 1 / 2 std | "
          "RMS error/std | the same with the fit's std alone | model error that makes "
          "that RMS one")
    for what, v in rows.items():
        e, s, a = np.array(v).T
        z, za = e / s, e / a
        print(f"{what}: {e.mean():+.4g} +- {e.std():.3g} | {np.median(s):.3g} | "
              f"{int(np.sum(np.abs(z) <= 1))}/{len(z)}, {int(np.sum(np.abs(z) <= 2))}/{len(z)} "
              f"| {np.sqrt(np.mean(z**2)):.2f} | {np.sqrt(np.mean(za**2)):.2f} "
              f"| {model_error(e, a):.3g}")


def main() -> None:
    from shoveld.sim.effects import SIM_EFFECTS

    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10, help="machines per effect")
    ap.add_argument("--effects", default=",".join(EFFECTS), metavar="NAME,...")
    ap.add_argument("--seed-offset", type=int, default=5000)
    ap.add_argument("--machine", choices=MACHINES, default="drawn",
                    help="which machine each case simulates (to take a bias apart)")
    ap.add_argument("--magnitude", type=float,
                    help="every case at this magnitude instead of one drawn from the range")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", help="write every case to this file (JSON lines)")
    args = ap.parse_args()
    names = [n for n in args.effects.split(",") if n]
    bad = [n for n in names if n not in EFFECTS]
    if bad:
        raise SystemExit(f"--effects: no truth for {bad}; expected some of {list(EFFECTS)}")
    rng = np.random.default_rng(20261128)
    jobs = [{"effect": n, "magnitude": float(round(rng.uniform(*SIM_EFFECTS[n].typical_range), 3)),
             "seed": args.seed_offset + 100 * i + s, "machine": args.machine}
            for i, n in enumerate(names) for s in range(args.seeds)]
    if args.magnitude is not None:
        for j in jobs:
            j["magnitude"] = args.magnitude
    print(f"{len(jobs)} cases on {args.jobs} processes...", file=sys.stderr)
    t0 = time.perf_counter()
    results = run_cases(one, jobs, args.jobs, args.json)
    summary(results)
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
