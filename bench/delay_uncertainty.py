"""Does the time skew's reported uncertainty cover the true delays?

For each case a realistic machine is drawn (``Machine.draw``), its two calibration
trials simulated with the MTi's stream late by the hidden skew (the bench form: the
laser on time) and, in most cases, a second effect beside it; then the skew's delays
are searched as ``shoveld diagnose`` searches them, beside the base model. Prints,
per device (the MTi late by the skew, the laser on time), the error of the found
lateness, the search's own standard error (the sandwich over blocks of the trials,
with the grid's rounding), the total the report gives (with the model's error,
``SensorTimeSkew.model_error_s``) and how often the truth lies within one and two of
them, with the RMS of error over standard deviation (1 when the figure is honest), and
the model's error that would make that RMS 1 on these cases.

* ``--cases bench``: the 53 time-skew cases of the detection matrix (its three single
  skew cases and the skew pairs of its ten sets of fifteen): the cases the model's
  error was measured on;
* ``--cases fresh --n 50 --seed 4141``: new machines and draws (seeds 3000 + i), the
  skew with a partner drawn among the six effects of the pairs or none: the check.

Usage: ``.venv/bin/python bench/delay_uncertainty.py [--cases fresh] [--n 50]
[--seed 4141] [--jobs 2] [--json out.jsonl]``
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from _run import model_error, run_cases  # noqa: E402

PAIR_EFFECTS = ("current_saturation", "ground_slope", "hoist_rope_mass",
                "load_dependent_friction", "sensor_time_skew", "swing_centrifugal")
MATRIX_SETS = ((20261122, 0), (7, 50), (11, 100), (13, 150), (17, 200), (19, 250), (23, 300),
               (29, 350), (31, 400), (37, 450))
"""(--draw-seed, --seed-offset) of the detection matrix's ten sets of pairs (README)."""
SKEW = "sensor_time_skew"


def bench_cases() -> list[dict[str, Any]]:
    """The matrix's skew cases, drawn by ``bench/diagnose_matrix.py``'s own ``draw_jobs``:
    the singles (``--seeds 3``, the default draw) and the pairs of its sets."""
    from diagnose_matrix import draw_jobs

    jobs = draw_jobs(3, 0, 0, None, 24, 20261122, 0)
    for draw, off in MATRIX_SETS:
        jobs += draw_jobs(0, 0, 15, list(PAIR_EFFECTS), 24, draw, off)
    return [{"spec": j["spec"], "seed": j["seed"]} for j in jobs
            if j["kind"] in ("single", "pair") and SKEW in j["spec"]]


def fresh_cases(n: int, seed: int) -> list[dict[str, Any]]:
    """New machines: the skew alone or beside one other effect, drawn uniformly."""
    from shoveld.sim.effects import SIM_EFFECTS

    rng = np.random.default_rng(seed)
    out = []
    for s in range(n):
        spec = {SKEW: float(round(rng.uniform(*SIM_EFFECTS[SKEW].typical_range), 3))}
        other = str(rng.choice([p for p in PAIR_EFFECTS if p != SKEW] + ["none"]))
        if other != "none":
            spec[other] = float(round(rng.uniform(*SIM_EFFECTS[other].typical_range), 3))
        out.append({"spec": spec, "seed": 3000 + s})
    return out


def one(job: dict[str, Any]) -> dict[str, Any]:
    """Simulate one machine's two trials and search the skew's delays on them."""
    from shoveld.identify.calibrate import Calibrator
    from shoveld.model.effects import SensorTimeSkew
    from shoveld.model.model import Model
    from shoveld.sim.effects import make_effects
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_calibration

    base = 1000 * job["seed"]
    machine = Machine.draw(base)
    trials = [simulate_calibration(load, base + i + 1, machine=machine,
                                   effects=make_effects(dict(job["spec"]), form="bench")).table
              for i, load in enumerate((0.0, 8420.0))]
    t0 = time.perf_counter()
    # the equation-error form: the search itself uses it, and the output-error fit after
    # it would not move the delays
    cal = Calibrator(Model.from_names([SKEW]), method="equation").fit(trials)
    assert cal.params_ is not None
    h = cal.params_.hyper[SKEW]
    truth = job["spec"][SKEW] / 1000.0  # the bench form: the MTi late, the laser on time
    out = {**job, "search_s": time.perf_counter() - t0}
    for dev, found, true in (("mti", h["delay_s"], truth),
                             ("laser", h["delay_s"] + h["crowd_lag_s"], 0.0)):
        a = float(h[f"{dev}_late_std_s"])
        out[dev] = {"error_s": found - true, "std_a_s": a,
                    "std_s": math.hypot(a, SensorTimeSkew.model_error_s[dev])}
    return out


def summary(results: list[dict[str, Any]]) -> None:
    from shoveld.model.effects import SensorTimeSkew

    print(f"{len(results)} cases; ms; one and two: cases whose truth lies within one and "
          "two standard deviations")
    for dev in ("mti", "laser"):
        e = np.array([r[dev]["error_s"] for r in results]) * 1000
        a = np.array([r[dev]["std_a_s"] for r in results]) * 1000
        s = np.array([r[dev]["std_s"] for r in results]) * 1000
        need = model_error(e, a)
        print(f"{dev:5s}: error {e.mean():+.1f} +- {e.std():.1f} (RMS {np.sqrt(np.mean(e**2)):.1f}"
              f", largest {np.abs(e).max():.0f})")
        for label, sd in (("search's own", a), ("reported", s)):
            z = e / sd
            rms_z = float(np.sqrt(np.mean(z**2)))
            print(f"       {label:13s} std median {np.median(sd):5.1f} [{sd.min():.1f}, "
                  f"{sd.max():.1f}]: one {int(np.sum(np.abs(z) <= 1))}/{len(z)}, two "
                  f"{int(np.sum(np.abs(z) <= 2))}/{len(z)}, RMS error/std {rms_z:.2f}")
        print(f"       model error that makes the RMS error/std 1 here: {need:.1f} (given: "
              f"{1000 * SensorTimeSkew.model_error_s[dev]:.1f})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", choices=("bench", "fresh"), default="fresh")
    ap.add_argument("--n", type=int, default=50, help="fresh cases")
    ap.add_argument("--seed", type=int, default=4141, help="seed of the fresh cases' draws")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", help="write every case to this file (JSON lines)")
    args = ap.parse_args()
    jobs = bench_cases() if args.cases == "bench" else fresh_cases(args.n, args.seed)
    print(f"{len(jobs)} {args.cases} cases on {args.jobs} processes...", file=sys.stderr)
    t0 = time.perf_counter()
    results = run_cases(one, jobs, args.jobs, args.json)
    summary(results)
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
