"""Detection matrix of ``shoveld diagnose`` on simulated data with hidden effects.

For every effect of the simulator and every seed: a magnitude drawn from the
effect's ``typical_range``, two calibration trials (empty, 8,420 kg) and a session
of dig cycles (3-35 t, about half the passes scale-verified), all with the effect
and sensor noise; then the diagnosis. Prints

* the detection matrix (hidden effect -> first effect named, or "none"),
* the false-alarm rate (data without any effect where something was named),
* pairs of effects: how often both are found, and in the order of their payload
  impact (each effect's base-model payload error when simulated alone, same seeds),
* per effect, the held-out payload RMS of the base and the extended model (kg and %
  of the 35 t rated load), over the seeds.

    .venv/bin/python bench/diagnose_matrix.py [--seeds 6] [--null 20] [--pairs 10]
                                              [--pair-effects NAME,...] [--passes 24]
                                              [--jobs 2] [--json out.json]
                                              [--progress cases.jsonl] [--cache DIR]
                                              [--select KEY=VALUE ...]

``--progress`` keeps each case with every step's candidates and verdicts;
``--cache`` keeps each case's fitted models, so a later run with other ``--select``
settings (``shoveld.diagnose.select.SelectionConfig``) judges the same fits.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import math
import os
import pickle
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

# One BLAS thread per worker: two workers with two threads each on a 2-core machine
# spin against each other and ran ten times slower.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from shoveld.diagnose.core import MODELLED_BY_BASE  # noqa: E402

RATED = 35000.0


def simulate_session(spec: dict[str, float], seed: int, passes: int, ideal: bool = False
                     ) -> tuple[list[Any], Any]:
    """The two calibration trials' tables and the session of cycles (a ``SimResult``,
    its passes' truth with it) of one case, the effects of ``spec`` in their bench form."""
    from shoveld.sim.effects import make_effects
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import simulate_calibration, simulate_cycles

    def fx() -> list[Any]:
        return make_effects(dict(spec), form="bench")

    base = 1000 * seed
    machine = Machine.ideal() if ideal else Machine.draw(base)
    c0 = simulate_calibration(0.0, base + 1, effects=fx(), machine=machine)
    c1 = simulate_calibration(8420.0, base + 2, effects=fx(), machine=machine)
    ops = simulate_cycles(passes, base + 3, payload_range=(3000.0, 35000.0),
                          truck_target_kg=None, verified_fraction=0.5, effects=fx(),
                          machine=machine)
    return [c0.table, c1.table], ops


def simulate(spec: dict[str, float], seed: int, passes: int, ideal: bool = False
             ) -> tuple[list[Any], list[Any], float]:
    calib, ops = simulate_session(spec, seed, passes, ideal)
    crb = float(np.mean([p.crb_kg for p in ops.passes if p.verified]))
    return calib, [ops.table], crb


def one(job: dict[str, Any]) -> dict[str, Any]:
    """Simulate and diagnose one case (runs in a worker process)."""
    from shoveld.diagnose import diagnose

    t0 = time.perf_counter()
    calib, measured, crb = simulate(job["spec"], job["seed"], job["passes"], job["ideal"])
    t1 = time.perf_counter()
    if job.get("base_only"):
        from shoveld.diagnose.data import DataSet
        from shoveld.diagnose.fit import evaluate
        from shoveld.model.model import Model

        ds = DataSet(calib, measured)
        valid = [f.use for f in ds.view(Model.from_names([])).measured]
        ev = evaluate(ds, [], {}, np.ones(2), valid)
        e = ev.payload_errors(ds.passes)
        return {**job, "base_rms": float(np.sqrt(np.mean(e**2))), "crb": crb}
    from shoveld.diagnose.select import SelectionConfig

    cache: dict[tuple[str, ...], Any] = {}
    path = (os.path.join(job["cache"], hashlib.sha1(_key(job).encode()).hexdigest()[:16]
                         + ".pkl") if job.get("cache") else None)
    if path and os.path.exists(path):
        with open(path, "rb") as f:
            cache = pickle.load(f)
    d = diagnose(calib, measured, cfg=SelectionConfig(**job.get("select", {})),
                 engine=False, cache=cache)
    if path:
        with open(path, "wb") as out:
            pickle.dump(d.selection.evaluations, out)
    t2 = time.perf_counter()
    b = d.payload("base")
    x = d.payload("extended")
    return {**job, "found": d.found, "crb": crb, "base_rms": b.get("rms_kg", math.nan),
            "ext_rms": x.get("rms_kg", math.nan), "base_mean": b.get("mean_kg", math.nan),
            "ext_mean": x.get("mean_kg", math.nan), "sim_s": t1 - t0, "diag_s": t2 - t1,
            "scores": {c.name: round(c.gain, 4) for c in d.selection.steps[0].candidates},
            "steps": [{"model": st.model, "chosen": st.chosen, "removed": st.removed,
                       "candidates": [c.as_dict() for c in st.candidates],
                       "pairs": [c.as_dict() for c in st.pairs]}
                      for st in d.selection.steps]}


def _key(case: dict[str, Any]) -> str:
    """A case by what it simulates (its data), not by how it is judged."""
    return json.dumps([case["kind"], case["truth"], case["seed"], case["spec"]], sort_keys=True)


def run_all(jobs: list[dict[str, Any]], workers: int, progress: str | None
            ) -> list[dict[str, Any]]:
    """Every case on ``workers`` processes; each appended to ``progress`` as it ends."""
    with ProcessPoolExecutor(workers) as ex:
        futures = [ex.submit(one, j) for j in jobs]
        for f in as_completed(futures):
            if progress:
                with open(progress, "a") as out:
                    out.write(json.dumps(f.result(), default=str) + "\n")
        return [f.result() for f in futures]


def _settings(items: list[str]) -> dict[str, Any]:
    """``--select KEY=VALUE`` items as SelectionConfig keywords, typed as the defaults."""
    from dataclasses import fields

    from shoveld.diagnose.select import SelectionConfig

    known = {f.name: f for f in fields(SelectionConfig)}
    default = SelectionConfig()
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or key not in known:
            raise SystemExit(f"--select {item!r}: expected KEY=VALUE with KEY one of "
                             f"{sorted(known)}")
        kind = type(getattr(default, key))
        try:
            out[key] = (value.lower() in ("1", "true", "yes") if kind is bool
                        else kind(value))
        except ValueError:
            raise SystemExit(f"--select {item!r}: {key} expects a {kind.__name__}") from None
    return out


def draw_jobs(seeds: int, null: int, pairs: int, pair_effects: list[str] | None,
              passes: int, draw_seed: int, seed_offset: int) -> list[dict[str, Any]]:
    """The matrix's cases: per effect ``seeds`` singles, ``null`` clean machines and
    ``pairs`` pairs drawn among ``pair_effects`` (all but those the base model carries
    when None), each pair with its two effects alone on the same machine; magnitudes
    and pairs drawn with ``draw_seed``, machines and sessions offset by ``seed_offset``
    (other benches draw the matrix's cases through this, so that they stay the same)."""
    from shoveld.sim.effects import SIM_EFFECTS

    names = sorted(SIM_EFFECTS)
    rng = np.random.default_rng(draw_seed)
    off = seed_offset
    jobs: list[dict[str, Any]] = []
    for name in names:
        lo, hi = SIM_EFFECTS[name].typical_range
        for s in range(seeds):
            mag = float(round(rng.uniform(lo, hi), 3))
            jobs.append({"kind": "single", "truth": name, "spec": {name: mag},
                         "seed": off + 100 + s, "passes": passes})
    for s in range(null):
        jobs.append({"kind": "null", "truth": "none", "spec": {}, "seed": off + 500 + s,
                     "passes": passes})
    pool = [n for n in (pair_effects or names) if n not in MODELLED_BY_BASE]
    unknown = [n for n in pool if n not in SIM_EFFECTS]
    if unknown:
        raise ValueError(f"unknown effect(s) {unknown}; expected some of {names}")
    combos = list(itertools.combinations(pool, 2))
    for s, k in enumerate(rng.choice(len(combos), size=min(pairs, len(combos)),
                                     replace=False)):
        a, b = combos[int(k)]
        spec = {n: float(round(rng.uniform(*SIM_EFFECTS[n].typical_range), 3)) for n in (a, b)}
        jobs.append({"kind": "pair", "truth": f"{a}+{b}", "spec": spec, "seed": off + 800 + s,
                     "passes": passes})
        for n in (a, b):
            jobs.append({"kind": "alone", "truth": n, "spec": {n: spec[n]}, "seed": off + 800 + s,
                         "passes": passes, "base_only": True, "pair": f"{a}+{b}"})
    return jobs


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=6, help="seeds per effect")
    ap.add_argument("--null", type=int, default=20, help="seeds without any effect")
    ap.add_argument("--pairs", type=int, default=10, help="random pairs of effects")
    ap.add_argument("--pair-effects", default="", metavar="NAME,...",
                    help="draw the pairs among these effects only (e.g. those whose typical "
                         "range moves the payload by >= 0.5 %% of rated on its own)")
    ap.add_argument("--passes", type=int, default=24)
    ap.add_argument("--draw-seed", type=int, default=20261122,
                    help="seed of the magnitudes' and pairs' draws (another gives other "
                         "cases: a rule chosen on one set of cases checked on another)")
    ap.add_argument("--seed-offset", type=int, default=0,
                    help="added to every case's machine and session seed (other machines)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", help="write all cases to this file")
    ap.add_argument("--load", help="print the matrix of cases saved by --progress or --json "
                                   "instead of running them")
    ap.add_argument("--progress", help="append each case to this file (JSON lines) as it "
                                       "ends; a run given the same file again skips the "
                                       "cases it holds (resume)")
    ap.add_argument("--select", action="append", default=[], metavar="KEY=VALUE",
                    help="a selection setting (shoveld.diagnose.select.SelectionConfig) other "
                         "than its default, e.g. payload_alpha=0.1; may be repeated")
    ap.add_argument("--cache", metavar="DIR",
                    help="keep each case's fitted models here and reuse them on a later run "
                         "(the same cases judged by other --select settings in minutes)")
    ap.add_argument("--ideal", action="store_true",
                    help="the ideal simulator (the old matrix); default: realistic machines, "
                         "one drawn per case")
    args = ap.parse_args()

    from shoveld.sim.effects import SIM_EFFECTS

    names = sorted(SIM_EFFECTS)
    try:
        jobs = draw_jobs(args.seeds, args.null, args.pairs,
                         args.pair_effects.split(",") if args.pair_effects else None,
                         args.passes, args.draw_seed, args.seed_offset)
    except ValueError as e:
        raise SystemExit(f"--pair-effects: {e}") from None
    t0 = time.perf_counter()
    select = _settings(args.select)
    if args.cache:
        os.makedirs(args.cache, exist_ok=True)
    for j in jobs:
        j["ideal"] = bool(args.ideal)
        if select:
            j["select"] = select
        if args.cache:
            j["cache"] = args.cache
    if args.load:
        with open(args.load) as f:
            text = f.read()
        results = (json.loads(text) if text.lstrip().startswith("[")
                   else [json.loads(line) for line in text.splitlines() if line.strip()])
        names = sorted({r["truth"] for r in results if r["kind"] == "single"}) or names
        args.seeds = max((sum(1 for r in results if r["kind"] == "single" and r["truth"] == n)
                          for n in names), default=0)
    else:
        done: list[dict[str, Any]] = []
        if args.progress and os.path.exists(args.progress):
            # resume: the cases a stopped run already finished are not run again
            with open(args.progress) as f:
                done = [json.loads(line) for line in f if line.strip()]
            keys = {_key(r) for r in done}
            jobs = [j for j in jobs if _key(j) not in keys]
        results = done + run_all(jobs, args.jobs, args.progress)
    print(f"{'ideal simulator' if args.ideal else 'realistic machines'}; effects the base "
          f"model carries ({', '.join(sorted(MODELLED_BY_BASE))}) count as right when "
          "nothing is named")
    wall = time.perf_counter() - t0

    single = [r for r in results if r["kind"] == "single"]
    labels = [*names, "none"]
    print(f"Detection matrix ({args.seeds} seeds per effect, magnitude drawn from the "
          f"effect's typical range, {args.passes} passes, ~half verified):")
    w = max(len(n) for n in labels) + 1
    short = {n: n[:7] for n in labels}
    print(" " * w + " ".join(f"{short[n]:>7s}" for n in labels))
    for t in names:
        row = [r for r in single if r["truth"] == t]
        counts = {n: sum(1 for r in row if (r["found"][0] if r["found"] else "none") == n)
                  for n in labels}
        print(f"{t:<{w}s}" + " ".join(f"{counts[n]:7d}" for n in labels))
    def right(r: dict[str, Any]) -> bool:
        if r["truth"] in MODELLED_BY_BASE:
            return not r["found"]
        return bool(r["found"]) and r["found"][0] == r["truth"]

    hits = sum(1 for r in single if right(r))
    ns = max(1, len(single))
    print(f"named first correctly: {hits}/{len(single)} ({100 * hits / ns:.0f} %)")
    extra = [r for r in single if any(n != r["truth"] for n in r["found"])]
    print(f"extra names (a name that is not the hidden effect): {len(extra)}/{len(single)} "
          f"({100 * len(extra) / ns:.0f} %)"
          + ("".join(f"\n  {r['truth']} (seed {r['seed']}): {r['found']}" for r in extra)))

    null = [r for r in results if r["kind"] == "null"]
    if null:
        # What the effect does to the payload, net of the machine's own floor: the base
        # model's held-out RMS with it, in quadrature over the median without any effect.
        floor = float(np.median([r["base_rms"] for r in null]))
        big = [r for r in single if r["truth"] not in MODELLED_BY_BASE
               and r["base_rms"] ** 2 - floor**2 >= (0.005 * RATED) ** 2]
        hb = sum(1 for r in big if right(r))
        print(f"of which the effect moves the payload by >= 0.5 % of rated "
              f"(sqrt(base RMS^2 - {floor:.0f}^2 kg^2) >= {0.005 * RATED:.0f} kg): "
              f"named first {hb}/{len(big)}")

    fa = [r for r in null if r["found"]]
    print(f"\nFalse alarms on data without any effect: {len(fa)}/{len(null)} "
          f"({100 * len(fa) / max(1, len(null)):.0f} %)"
          + (": " + ", ".join(f"seed {r['seed']}: {r['found']}" for r in fa) if fa else ""))
    if null:
        nb = np.array([r["base_rms"] for r in null])
        print(f"  base model payload RMS without effects: median {np.median(nb):.0f} kg "
              f"({100 * np.median(nb) / RATED:.2f} %)")

    pair_rows = [r for r in results if r["kind"] == "pair"]
    alone = {(r["pair"], r["truth"]): r["base_rms"] for r in results if r["kind"] == "alone"}
    both = ordered = one_first = extras = 0
    sized: list[bool] = []  # both effects of a pair at the size (>= 0.5 % of rated)
    print(f"\nPairs of effects ({len(pair_rows)}):")
    for r in pair_rows:
        a, b = r["truth"].split("+")
        if (r["truth"], a) not in alone or (r["truth"], b) not in alone:
            continue  # a stopped run (--load of a partial --progress file)
        size = sorted((a, b), key=lambda n: -alone[(r["truth"], n)])
        got_both = set(r["found"][:2]) == {a, b}
        in_order = got_both and r["found"][:2] == size
        both += got_both
        ordered += in_order
        one_first += bool(r["found"]) and r["found"][0] in (a, b)
        extras += any(n not in (a, b) for n in r["found"])
        if null and all(alone[(r["truth"], n)] ** 2 - floor**2 >= (0.005 * RATED) ** 2
                        for n in (a, b)):
            sized.append(got_both)
        print(f"  {a} ({r['spec'][a]:g}, alone {alone[(r['truth'], a)]:.0f} kg) + {b} "
              f"({r['spec'][b]:g}, alone {alone[(r['truth'], b)]:.0f} kg) -> {r['found']}"
              f"{'  both' if got_both else ''}{', in order of size' if in_order else ''}")
    if pair_rows:
        print(f"both found: {both}/{len(pair_rows)} ({100 * both / len(pair_rows):.0f} %), "
              f"both and in order of payload impact: {ordered}/{len(pair_rows)} "
              f"({100 * ordered / len(pair_rows):.0f} %); one of the two named first: "
              f"{one_first}/{len(pair_rows)}; a name that is neither: {extras}/{len(pair_rows)}")
        if null:
            print(f"of which both effects move the payload by >= 0.5 % of rated alone: both "
                  f"found {sum(sized)}/{len(sized)}")

    print("\nPer-effect gain: held-out payload RMS over the verified passes, base -> extended "
          "(mean over seeds; % of the 35 t rated load); 'halved' counts cases where the "
          "extended RMS is at most half the base's or within 1.5 x the Cramer-Rao bound:")
    for t in names:
        row = [r for r in single if r["truth"] == t]
        if not row:
            continue
        b = np.array([r["base_rms"] for r in row])
        ext = np.array([r["ext_rms"] for r in row])
        cut = sum(1 for r in row if r["ext_rms"] < r["base_rms"])
        halved = sum(1 for r in row if r["ext_rms"] <= max(0.5 * r["base_rms"],
                                                             1.5 * r["crb"]))
        print(f"  {t:<{w}s} {b.mean():6.0f} kg ({100 * b.mean() / RATED:.2f} %) -> "
              f"{ext.mean():6.0f} kg ({100 * ext.mean() / RATED:.2f} %)   cut in {cut}/{len(row)},"
              f" halved in {halved}/{len(row)}")
    diag = np.array([r["diag_s"] for r in results if "diag_s" in r])
    print(f"\n{len(results)} cases in {wall:.0f} s wall ({args.jobs} workers); diagnosis of a "
          f"{args.passes}-pass session: median {np.median(diag):.1f} s")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1, default=float)


if __name__ == "__main__":
    main()
