"""Every event of ``estimate_table`` from two source trees, compared exactly.

A speed change to the engine must not change what it reports. This runs the same
simulated tables through the engine of this tree and of another one (a ``git archive``
or ``git worktree`` of the code before the change) and compares every live estimate
(time, phase, payload, std, valid), every pass and every truck, bit for bit. The
tables cover what the engine's fast paths skip: five 50 Hz runs of 40 passes, one at
100 Hz, one with holes (unknown angles, runs of them, skipped ticks) and one with the
causal Kalman rates for the payload (``payload_rates="kalman"``).

    git archive BASE_COMMIT | tar -x -C /tmp/engine-base
    .venv/bin/python bench/engine_identical.py /tmp/engine-base

Exit status 0 when every event is identical. Takes about a minute on one core.
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
PARAMS = ROOT / "hil_fixtures" / "captures" / "daemon-e2e" / "params.toml"


def with_holes(table: Any, seed: int) -> Any:
    """The table with unknown angles (single samples and runs) and skipped ticks (rows
    dropped), as a corrupt frame and a loaded host make them."""
    import numpy as np

    from shoveld.signals.table import SignalsTable

    rng = np.random.default_rng(seed)
    cols = {n: np.array(v, copy=True) for n, v in table.columns.items()}
    n = len(cols["time_s"])
    for name in ("handle_deg", "crowd_m", "swing_deg"):
        cols[name][rng.choice(n, n // 200, replace=False)] = np.nan
        for s0 in rng.choice(n - 100, 5):
            cols[name][s0:s0 + rng.integers(10, 80)] = np.nan
    keep = np.ones(n, bool)
    keep[rng.choice(n, n // 100, replace=False)] = False
    for s0 in rng.choice(n - 10, 20):
        keep[s0:s0 + rng.integers(2, 8)] = False
    return SignalsTable.from_arrays(meta=dict(table.meta), **{k: v[keep] for k, v in cols.items()})


def dump(out: Path) -> None:
    """Run this interpreter's ``shoveld`` over the tables; pickle every event."""
    from shoveld.engine.loop import EngineConfig
    from shoveld.engine.offline import estimate_table
    from shoveld.model.params import load_params
    from shoveld.sim.scenario import simulate_cycles

    params = load_params(PARAMS)
    cases: dict[str, tuple[Any, EngineConfig | None]] = {
        f"seed {s}": (simulate_cycles(40, seed=s).table, None) for s in range(1, 6)}
    cases["100 Hz"] = (simulate_cycles(20, seed=6, rate_hz=100.0).table, None)
    cases["holes"] = (with_holes(simulate_cycles(40, seed=7).table, 7), None)
    cases["kalman rates"] = (simulate_cycles(20, seed=8).table,
                             EngineConfig(payload_rates="kalman"))
    events = {}
    for name, (table, cfg) in cases.items():
        e = estimate_table(table, params, cfg, keep_live=True)
        events[name] = ([(x.time_s, x.phase, x.payload_kg, x.std_kg, x.valid) for x in e.live],
                        [p.as_dict() | {"raw": (p.payload_kg, p.std_kg)} for p in e.passes],
                        [t.as_dict() for t in e.trucks])
    out.write_bytes(pickle.dumps(events))


def same(x: Any, y: Any) -> bool:
    """Equal, NaN equal to NaN (a live estimate before the first block has no payload)."""
    if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
        return True
    if isinstance(x, tuple) and isinstance(y, tuple):
        return len(x) == len(y) and all(same(a, b) for a, b in zip(x, y, strict=True))
    return bool(x == y)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("base", type=Path, help="the other source tree (its shoveld/ is used)")
    ap.add_argument("--dump", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.dump:
        dump(args.dump)
        return 0
    with tempfile.TemporaryDirectory() as d:
        got = {}
        for label, tree in (("base", args.base.resolve()), ("this", ROOT)):
            path = Path(d) / f"{label}.pkl"
            env = {**os.environ, "PYTHONPATH": str(tree)}
            subprocess.run([sys.executable, __file__, str(args.base), "--dump", str(path)],
                           env=env, check=True)
            got[label] = pickle.loads(path.read_bytes())
    bad = 0
    for name, (live, passes, trucks) in got["base"].items():
        live2, passes2, trucks2 = got["this"][name]
        diff = sum(not same(a, b) for a, b in zip(live, live2, strict=False))
        diff += abs(len(live) - len(live2))
        ok = diff == 0 and repr(passes) == repr(passes2) and repr(trucks) == repr(trucks2)
        bad += not ok
        print(f"{name:13s} {len(live):6d} live estimates, {len(passes):2d} passes, "
              f"{len(trucks):2d} trucks: {'identical' if ok else f'DIFFER ({diff} live)'}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
