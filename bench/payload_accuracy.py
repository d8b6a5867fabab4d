"""Payload accuracy and identification statistics over many simulated machines.

A seed draws a whole machine (mechanics, drive, sensors: ``shoveld.sim.machine``).
Per machine: empty and 8,420 kg calibration trials (held poses, free motion, fast
strokes), identification, then passes of 3 to 35 t. Prints, realistic machines
beside the ideal simulator:

* per-pass payload error: mean, RMS, p95 |error| (kg and % of the 35 t rated load),
  RMS against the mean Cramer-Rao bound of the current noise, valid passes, and how
  often the reported std covers the error (1 and 2 sigma);
* the same for the passes whose lift ran on a weakened hoist field;
* the thesis's identification (currents in the regressor) against the output-error
  one, on the same realistic data;
* the parameter coverage table over ``--coverage`` machines: per parameter, the share
  of machines whose true value lies within +-2 standard errors, and the mean error
  over the mean standard error (bias).

    .venv/bin/python bench/payload_accuracy.py [--machines 18] [--passes 60]
                                               [--coverage 120] [--jobs 2]
                                               [--window S --polyorder N]
                                               [--payload-window S --payload-polyorder N]
                                               [--no-angle-noise] [--settle-test-z Z]

``--window``/``--polyorder`` set the angles' Savitzky-Golay smoothing of identification,
``--payload-window``/``--payload-polyorder`` the payload equations' (recorded in the
params, which the engine follows); docs/engine.md, "Smoothing" and "The payload's own
smoothing".
``--no-angle-noise`` identifies without the angles' errors-in-variables correction
(``calibrate --no-angle-noise``; on by default since 2026-11-26); docs/engine.md, "The
angles' noise".
"""

from __future__ import annotations

import argparse
import math
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from shoveld.model.terms import knot_group

RATED = 35000.0


SMOOTHING: dict[str, Any] = {}
"""Calibrator keywords from the command line (set in each worker by ``_init``)."""


ENGINE: dict[str, Any] = {}
"""EngineConfig keywords from the command line (the same way)."""


def _init(smoothing: dict[str, Any], engine: dict[str, Any] | None = None) -> None:
    SMOOTHING.update(smoothing)
    ENGINE.update(engine or {})


def add_identification_args(ap: argparse.ArgumentParser) -> None:
    """The identification's options (``calibrate``'s) and the engine's settle test, for
    this bench and its siblings."""
    ap.add_argument("--window", type=float, help="smoothing window, s (default: calibrate's)")
    ap.add_argument("--polyorder", type=int, help="smoothing order (default: calibrate's)")
    ap.add_argument("--payload-window", type=float,
                    help="the payload equations' smoothing window, s (default: calibrate's)")
    ap.add_argument("--payload-polyorder", type=int,
                    help="the payload equations' smoothing order (default: calibrate's)")
    ap.add_argument("--angle-noise", action=argparse.BooleanOptionalAction,
                    help="the angles' errors-in-variables correction (default: calibrate's, "
                         "on; --no-angle-noise: off)")
    ap.add_argument("--settle-test-z", type=float, metavar="Z",
                    help="the engine's test of the settle time's samples, in standard "
                         "errors (default: the engine's; 0: never keep them, as before "
                         "2026-11-27)")


def engine_options(args: argparse.Namespace) -> dict[str, Any]:
    """EngineConfig keywords of the options given (for ``_init`` in each worker)."""
    return {} if args.settle_test_z is None else {"settle_test_z": args.settle_test_z}


def identification_options(args: argparse.Namespace) -> dict[str, Any]:
    """Calibrator keywords of the options given (for ``_init`` in each worker)."""
    return {k: v for k, v in (("window_s", args.window), ("polyorder", args.polyorder),
                              ("payload_window_s", args.payload_window),
                              ("payload_polyorder", args.payload_polyorder),
                              ("position_noise", args.angle_noise))
            if v is not None}


def trials(machine: Any, seed: int) -> list[Any]:
    """The machine's two calibration trials: empty and 8,420 kg."""
    from shoveld.sim.scenario import simulate_calibration

    return [simulate_calibration(0.0, seed=10 * seed + 1, machine=machine).table,
            simulate_calibration(8420.0, seed=10 * seed + 2, machine=machine).table]


def calibrate(machine: Any, seed: int, method: str) -> Any:
    from shoveld.identify.calibrate import Calibrator

    return Calibrator(method=method, **SMOOTHING).fit(trials(machine, seed)).params_


def calibrate_with_verified(machine: Any, seed: int, n: int) -> Any:
    """The trials plus a session of ``n`` passes whose payloads a scale verified, as
    ``shoveld calibrate --verified`` identifies them."""
    from shoveld.diagnose.fit import calibrate_with_verified
    from shoveld.model.model import Model
    from shoveld.sim.scenario import simulate_cycles

    session = simulate_cycles(n, seed=10 * seed + 7, machine=machine,
                              payload_range=(3000.0, 35000.0), truck_target_kg=None,
                              verified_fraction=1.0)
    cal, _, _ = calibrate_with_verified(Model.from_names([]), trials(machine, seed),
                                        [session.table],
                                        **SMOOTHING)
    return cal.params_


def weighed(est: Any, tp: Any) -> Any:
    """The engine's pass of a simulated pass ``tp`` (the one that started within 2 s of
    its dig), if it was weighed, else None."""
    near = [p for p in est.passes if abs(p.start_s - tp.phases["dig"][0]) < 2.0]
    return near[0] if near and near[0].valid else None


def passes(params: Any, res: Any, table: Any = None, cfg: Any = None
           ) -> list[dict[str, float]]:
    """Each simulated pass of ``res`` against the engine's: truth, bound, error, std.
    ``table``: a changed copy of ``res.table`` to estimate instead; ``cfg``: an
    EngineConfig (default: the command line's)."""
    from shoveld.engine.loop import EngineConfig
    from shoveld.engine.offline import estimate_table

    table = res.table if table is None else table
    est = estimate_table(table, params, cfg or EngineConfig(**ENGINE))
    t = table.time
    field = table.columns["hoist_field_a"]
    out = []
    for tp in res.passes:
        got = weighed(est, tp)
        lift = (t >= tp.phases["lift"][0]) & (t < tp.phases["swing"][1])
        row = {"truth": tp.payload_kg, "crb": tp.crb_kg,
               "weak": bool(np.nanmin(field[lift]) < 60.0) if lift.any() else False,
               "valid": got is not None}
        if got is not None:
            row.update(err=got.payload_kg - tp.payload_kg, std=got.std_kg)
        out.append(row)
    return out


def one_machine(job: dict[str, Any]) -> dict[str, Any]:
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_cycles

    seed = job["seed"]
    out: dict[str, Any] = {"seed": seed}
    for kind in ("realistic", "ideal"):
        machine = Machine.draw(seed) if kind == "realistic" else Machine.ideal()
        methods = ("output", "equation") if kind == "realistic" else ("output",)
        res = simulate_cycles(job["passes"], seed=10 * seed + 3, machine=machine,
                              payload_range=(3000.0, 35000.0), truck_target_kg=None)
        empty = simulate_cycles(6, seed=10 * seed + 4, machine=machine, payloads=[0.0] * 6)
        known = simulate_cycles(6, seed=10 * seed + 5, machine=machine, payloads=[8420.0] * 6)
        for method in methods:
            p = calibrate(machine, seed, method)
            out[f"{kind}/{method}"] = {"passes": passes(p, res), "empty": passes(p, empty),
                                       "known": passes(p, known)}
        if kind == "realistic" and job.get("verified"):
            p = calibrate_with_verified(machine, seed, job["verified"])
            out["realistic/verified"] = {"passes": passes(p, res), "empty": passes(p, empty),
                                         "known": passes(p, known)}
    return out


def coverage_machine(job: tuple[int, int]) -> dict[str, Any]:
    """Identified against true parameters on one machine: (seed, verified passes)."""
    from shoveld.sim.machine import Machine

    seed, verified = job
    machine = Machine.draw(seed)
    p = (calibrate_with_verified(machine, seed, verified) if verified
         else calibrate(machine, seed, "output"))
    tr = machine.truth_for(p)
    return {n: (float(v), float(se), tr[n]) for n, v, se in
            zip(p.names, p.values, p.stderr, strict=True)}


def summary(label: str, rows: list[dict[str, float]]) -> None:
    ok = [r for r in rows if r["valid"]]
    if not ok:
        print(f"  {label:34s} no valid pass of {len(rows)}")
        return
    e = np.array([r["err"] for r in ok])
    s = np.array([r["std"] for r in ok])
    crb = np.array([r["crb"] for r in ok])
    r_ = RATED / 100
    rms = float(np.sqrt(np.mean(e**2)))
    p95 = float(np.percentile(np.abs(e), 95))
    print(f"  {label:34s} n={len(ok):4d}/{len(rows):<4d} valid {100 * len(ok) / len(rows):5.1f} %"
          f"  mean {e.mean():+6.0f} kg ({e.mean() / r_:+.2f} %)  RMS {rms:5.0f} kg"
          f"  p95 {p95:5.0f} kg ({p95 / r_:.2f} %)  RMS/CRB {rms / np.mean(crb):4.2f}"
          f"  within 1 std {np.mean(np.abs(e) < s):4.0%}, 2 std {np.mean(np.abs(e) < 2 * s):4.0%}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--machines", type=int, default=18,
                    help="realistic machines for the payload figures (6 gave RMS/CRB 1.54 "
                    "where 18 give 1.58: a few machines are too few)")
    ap.add_argument("--passes", type=int, default=60, help="passes per machine")
    ap.add_argument("--coverage", type=int, default=120,
                    help="machines for the parameter coverage table")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--verified", type=int, default=0, metavar="N",
                    help="also identify each realistic machine on its trials plus a session "
                         "of N scale-verified passes, and print its figures; the coverage "
                         "table is then of that identification (0: not)")
    add_identification_args(ap)
    args = ap.parse_args()
    smoothing = identification_options(args)
    engine = engine_options(args)
    if smoothing or engine:
        print(f"options: {smoothing | engine}")
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs, initializer=_init, initargs=(smoothing, engine)) as ex:
        res = list(ex.map(one_machine, [{"seed": s, "passes": args.passes,
                                         "verified": args.verified}
                                        for s in range(1, args.machines + 1)]))
        cov = list(ex.map(coverage_machine, [(s, args.verified) for s in
                                             range(101, 101 + args.coverage)]))
    print(f"per-pass payload error over {args.machines} machines x {args.passes} passes of "
          f"3-35 t (rated {RATED:.0f} kg); CRB = Cramer-Rao bound of the current noise, "
          "per pass")
    for key, label in (("realistic/output", "realistic machines, output error"),
                       ("realistic/verified", f"realistic, + {args.verified} verified passes"),
                       ("realistic/equation", "realistic, thesis form (before)"),
                       ("ideal/output", "ideal simulator, output error")):
        if key not in res[0]:
            continue
        rows = [r for m in res for r in m[key]["passes"]]
        summary(label, rows)
        if key.startswith("realistic"):
            summary("  of which weakened field in lift", [r for r in rows if r["weak"]])
            summary("  empty dipper", [r for m in res for r in m[key]["empty"]])
            summary("  known load 8,420 kg", [r for m in res for r in m[key]["known"]])
    for key in ("realistic/output", "realistic/verified"):
        if key not in res[0]:
            continue
        print(f"\nper machine ({key}): seed, passes, mean, RMS, p95, RMS/CRB")
        ratios = []
        for m in res:
            rows = [r for r in m[key]["passes"] if r["valid"]]
            e = np.array([r["err"] for r in rows])
            crb = np.mean([r["crb"] for r in rows])
            ratios.append(np.sqrt(np.mean(e**2)) / crb)
            print(f"  machine {m['seed']:3d}  {len(rows):3d}  {e.mean():+6.0f}  "
                  f"{np.sqrt(np.mean(e**2)):5.0f}  {np.percentile(np.abs(e), 95):5.0f}  "
                  f"{ratios[-1]:4.2f}")
        print(f"  RMS/CRB over the machines: min {min(ratios):.2f}, median "
              f"{np.median(ratios):.2f}, max {max(ratios):.2f}")

    if not cov:
        print(f"\n({time.perf_counter() - t0:.0f} s wall, {args.jobs} workers)")
        return
    how = f"trials + {args.verified} verified passes" if args.verified else "trials"
    print(f"\nparameter coverage over {len(cov)} realistic machines (output error, {how}): "
          "share within +-2 std err (goal >= 90 %), mean error / mean std err (goal < 0.5)")
    cov = [{knot_group(n): x for n, x in c.items()} for c in cov]
    names = list(dict.fromkeys(n for c in cov for n in c))
    for n in names:
        have = [c[n] for c in cov if n in c]
        v = np.array([x[0] for x in have])
        se = np.array([x[1] for x in have])
        tr = np.array([x[2] for x in have])
        err = v - tr
        within = np.mean(np.abs(err) <= 2 * se)
        bias = float(np.mean(err) / np.mean(se)) if np.mean(se) > 0 else math.nan
        rel = np.mean(np.abs(err) / np.abs(tr)) * 100 if np.all(np.abs(tr) > 1) else math.nan
        flag = "" if within >= 0.9 and abs(bias) < 0.5 else "   <- goal not met"
        print(f"  {n:8s} within 2 se {within:4.0%}  bias {bias:+5.2f} se  "
              f"mean |err| {rel:5.2f} %  median se/|truth| "
              f"{np.median(se / np.maximum(np.abs(tr), 1e-9)) * 100:5.2f} %"
              + (f"  ({len(have)} machines)" if len(have) < len(cov) else "") + flag)
    print(f"\n({time.perf_counter() - t0:.0f} s wall, {args.jobs} workers)")


if __name__ == "__main__":
    main()
