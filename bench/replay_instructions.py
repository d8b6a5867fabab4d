"""Instructions per 10 ms tick of ``replay --fast`` (callgrind): figures the load cannot move.

On this shared 2-core machine the wall-clock speed of the replay swings by a quarter
from run to run with what else runs; the instructions it executes do not. Each figure
is the difference of two processes under ``valgrind --tool=callgrind`` (hash seed
fixed) that do the same setup, one of them also the part measured, divided by the
replay's ticks:

* ``play``: ``ReplayRun.run`` on the committed capture (the bulk front end, the loop,
  the engine, the pass log, Zenoh);
* ``without engine``: the same play with ``Engine.step`` replaced by the results it
  gave in a first play (the front end, the loop's bookkeeping, the health message);
* ``front end``: the bulk feed's spans made alone, without the loop;
* ``engine alone``: a fresh ``Engine`` stepped over the samples a first play gave it
  (nothing else runs in the measured part; the Zenoh and OpenBLAS threads are idle);
* ``engine every tick``: the same with the payload blocks left out (``Engine._flush``
  only clears the batch), so the joint filters, phase machine, fixed-lag window and
  live estimate; the blocks are the two differenced.

Zenoh's and OpenBLAS's own threads add a little that varies: two runs of the same
code differ by up to about 1 % (1,000 instructions a tick).

Usage: ``.venv/bin/python bench/replay_instructions.py [--tree DIR ...] [--parts play,...]``
(each ``--tree`` a source tree, e.g. a ``git archive`` of the code before; default
this one). Needs valgrind; about a minute per part and tree.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # (at run time the tree measured may be an older one)
    from shoveld.engine.loop import Event
    from shoveld.replay.service import ReplayRun
    from shoveld.sample import Sample

ROOT = Path(__file__).resolve().parents[1]
PARTS = {"play": ("setup", "play"), "without engine": ("record", "stubbed"),
         "front end": ("build", "front"), "engine alone": ("samples", "steps"),
         "engine every tick": ("samples", "noblocks")}


def child(tree: Path, mode: str) -> None:
    """One measured process: the setup, and the part ``mode`` names."""
    import logging
    import threading

    from shoveld.daemon.assemble import Assembler
    from shoveld.daemon.config import parse_config
    from shoveld.model.params import load_params

    try:
        from shoveld.replay.service import fast_replay_service
    except ImportError:  # a tree from before 2026-11-29, when replay lived in the daemon
        from shoveld.daemon.replay import (  # type: ignore[no-redef, import-not-found]
            fast_replay_service,
        )

    logging.disable(logging.WARNING)
    cap = tree / "hil_fixtures" / "captures" / "daemon-e2e"
    params = load_params(cap / "params.toml")

    def make() -> ReplayRun:
        cfg = parse_config({"shovel": {"id": "bench", "params": str(cap / "params.toml"),
                                       "state_dir": tempfile.mkdtemp()},
                            "zenoh": {"listen": []}, "truck": {"target_kg": 62000.0}},
                           require_devices=False)
        return fast_replay_service(cap, cfg, params)

    # The engine's step is replaced on the instance below (method-assign): recording,
    # replaying or collecting what it was given.
    rr = make()
    svc = rr.service
    ticks = 0
    if mode in ("record", "stubbed"):  # a first play records what the engine gave
        svc.start()
        assert svc.engine is not None  # start made it
        results: list[list[Event]] = []
        step = svc.engine.step

        def recording(s: Sample) -> list[Event]:
            results.append(step(s))
            return results[-1]

        svc.engine.step = recording  # type: ignore[method-assign]
        rr.run(threading.Event())
        svc.flush()
        rr.close()
        rr = make()
        svc = rr.service
        svc.start()
        assert svc.engine is not None
        nxt = iter(results).__next__
        svc.engine.step = lambda s: nxt()  # type: ignore[method-assign]
        if mode == "stubbed":
            ticks = rr.run(threading.Event())["ticks"]
    elif mode in ("samples", "steps", "noblocks"):  # a first play gives the samples
        from shoveld.engine.loop import Engine

        svc.start()
        assert svc.engine is not None
        got: list[Sample] = []
        step = svc.engine.step

        def collecting(s: Sample) -> list[Event]:
            got.append(s)
            return step(s)

        svc.engine.step = collecting  # type: ignore[method-assign]
        rr.run(threading.Event())
        svc.flush()
        engine = Engine(svc.engine.params, svc.engine.cfg)
        if mode == "noblocks":
            engine._flush = engine.batch.clear  # type: ignore[method-assign]
        if mode != "samples":
            for s in got:
                engine.step(s)
            ticks = len(got)
    elif mode == "front":
        assert not isinstance(svc.assembler, Assembler)  # the bulk one, fast's default
        ticks = sum(len(span.samples) for span in svc.assembler.feed.spans())
    elif mode != "build":
        svc.start()
        if mode == "play":
            ticks = rr.run(threading.Event())["ticks"]
    svc.flush()
    print(f"ticks {ticks}")
    sys.stdout.flush()
    os._exit(0)  # no teardown to count


def instructions(tree: Path, mode: str) -> tuple[int, int]:
    """Instructions of one child process under callgrind, and the ticks it played."""
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "PYTHONHASHSEED": "0", "PYTHONPATH": str(tree)}
        r = subprocess.run(["valgrind", "--tool=callgrind",
                            f"--callgrind-out-file={tmp}/cg.out", sys.executable, __file__,
                            "--child", str(tree), mode],
                           capture_output=True, text=True, env=env, check=True)
    m = re.search(r"Collected : (\d+)", r.stderr)
    t = re.search(r"ticks (\d+)", r.stdout)
    if m is None or t is None:
        raise RuntimeError(f"callgrind gave no count:\n{r.stderr[-2000:]}")
    return int(m.group(1)), int(t.group(1))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", type=Path, action="append",
                    help="a source tree to measure (repeatable; default this one)")
    ap.add_argument("--parts", default=",".join(PARTS),
                    help=f"comma-separated, of: {', '.join(PARTS)}")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(Path(args.child[0]), args.child[1])
        return 0
    for tree in args.tree or [ROOT]:
        for part in args.parts.split(","):
            base, measured = PARTS[part]
            (n1, ticks), (n0, _) = instructions(tree, measured), instructions(tree, base)
            print(f"{tree}: {part}: {(n1 - n0) / ticks:,.0f} instructions a tick "
                  f"({ticks} ticks)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
