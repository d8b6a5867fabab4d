"""The verified passes' residuals against the trials' in one calibration
(``calibrate --verified``): the check ``calibrate`` makes of a model that lacks something
operation excites, where the daemon's misfit no longer can (it is read against this
calibration's noise, which takes the missing term in).

Each machine: its two trials (empty, 8,420 kg) and 24 passes a scale verified, with the
simulated effect if any; the ratio per channel (``shoveld.diagnose.fit.
passes_to_trials_rms``) against ``PASSES_TO_TRIALS_WARN``.

    .venv/bin/python bench/passes_to_trials.py [--machines 54] [--effects] [--swing 4]
"""

from __future__ import annotations

import argparse
from typing import Any


def ratio(seed: int, effects: dict[str, float] | None = None) -> dict[str, float]:
    from shoveld.diagnose.fit import calibrate_with_verified, passes_to_trials_rms
    from shoveld.model.model import Model
    from shoveld.sim.effects import make_effects
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_calibration, simulate_cycles

    machine = Machine.draw(seed)

    def fx() -> list[Any]:
        return make_effects(effects, form="bench") if effects else []

    trials = [simulate_calibration(kg, seed=10 * seed + k, machine=machine, effects=fx()).table
              for k, kg in ((1, 0.0), (2, 8420.0))]
    passes = simulate_cycles(24, seed=10 * seed + 7, machine=machine,
                             payload_range=(3000.0, 35000.0), truck_target_kg=None,
                             verified_fraction=1.0, effects=fx())
    cal, _, _ = calibrate_with_verified(Model.from_names([]), trials, [passes.table])
    return passes_to_trials_rms(cal)


def line(label: str, r: dict[str, float], warn: float) -> str:
    flag = "  WARNED" if max(r.values()) > warn else ""
    return f"  {label:34s} hoist {r['hoist']:.2f}  crowd {r['crowd']:.2f}{flag}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--machines", type=int, default=18, help="realistic machines, seeds 1..N")
    ap.add_argument("--swing", type=int, default=4,
                    help="machines (seeds 1..N) with a swing the model lacks, 2.5 and 6.5 m")
    ap.add_argument("--effects", action="store_true",
                    help="each other simulated effect at both ends of its range, seeds 1-2")
    args = ap.parse_args()
    from shoveld.payload.misfit import PASSES_TO_TRIALS_WARN as warn
    from shoveld.sim.effects import SIM_EFFECTS

    print(f"RMS of the verified passes' residual currents over the trials' (warned above "
          f"{warn:g})")
    seen = []
    for seed in range(1, args.machines + 1):
        r = ratio(seed)
        seen.append(r)
        print(line(f"realistic machine {seed}", r, warn), flush=True)
    if seen:
        for ch in ("hoist", "crowd"):
            xs = [r[ch] for r in seen]
            print(f"  {len(xs)} realistic machines, {ch}: {min(xs):.2f}-{max(xs):.2f}")
    for seed in range(1, args.swing + 1):
        for size in (2.5, 6.5):
            print(line(f"swing_centrifugal {size:g} m, machine {seed}",
                       ratio(seed, {"swing_centrifugal": size}), warn), flush=True)
    if args.effects:
        for name in sorted(SIM_EFFECTS):
            if name == "swing_centrifugal":
                continue
            for size in SIM_EFFECTS[name].typical_range:
                for seed in (1, 2):
                    print(line(f"{name} {size:g}, machine {seed}", ratio(seed, {name: size}),
                               warn), flush=True)


if __name__ == "__main__":
    main()
