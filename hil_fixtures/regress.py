"""Capture regression suite, after gpsd's: replay every committed capture, compare.

Each folder under ``hil_fixtures/captures/`` holds a capture, the ``params.toml``
it is replayed with, and ``expected.json``:

- ``passes`` / ``trucks``: what ``shoveld replay --fast`` (the real drivers on
  in-memory transports, the daemon's assembly and engine, a simulated clock)
  produced when the expectation was last rebuilt. Replay is deterministic, so a
  later run must reproduce these to the kilogram; a change that moves them is
  either a bug or an improvement, to be argued in its commit when rebuilding.
- ``true_payload_kg``: what the simulated shovel really carried, and
  ``offline_kg``: ``shoveld estimate`` on the signals table the capture was played
  from. The replay must stay within 1 % of rated load of both: the whole live
  path (devices, drivers, alignment to the tick) adds no bias of its own.

    python -m hil_fixtures.regress            # check every capture
    python -m hil_fixtures.regress --rebuild  # rewrite the replayed part of expected.json
"""

from __future__ import annotations

import argparse
import json
import tempfile
import threading
from pathlib import Path
from typing import Any

from hil_fixtures.net import free_port

CAPTURES = Path(__file__).resolve().parent / "captures"
RATED_KG = 35000.0




def replay(capture: Path, truck_target_kg: float) -> dict[str, list[dict[str, Any]]]:
    """Passes and closed trucks of a fast replay of ``capture``."""
    from shoveld.daemon.config import parse_config
    from shoveld.model.params import load_params
    from shoveld.replay.service import fast_replay_service

    params_path = capture / "params.toml"
    with tempfile.TemporaryDirectory() as state:
        cfg = parse_config({
            "shovel": {"id": "regress", "params": str(params_path), "state_dir": state},
            "zenoh": {"listen": [f"tcp/127.0.0.1:{free_port()}"]},
            "truck": {"target_kg": truck_target_kg}}, "<regress>", require_devices=False)
        rr = fast_replay_service(capture, cfg, load_params(params_path))
        got: dict[str, list[dict[str, Any]]] = {"pass": [], "truck": []}
        rr.service.on_event = lambda kind, msg: got[kind].append(msg) if kind in got else None
        try:
            rr.service.start()
            rr.run(threading.Event())
            rr.service.flush()
        finally:
            rr.close()
    from drivers.capture.format import read_capture

    t0 = float(read_capture(capture).start_unix)
    keep_p = ("pass", "truck", "payload_kg", "std_kg", "valid", "samples")
    keep_t = ("truck", "passes", "total_kg", "target_kg", "status")
    return {"passes": [{**{k: p[k] for k in keep_p}, "start_s": round(p["start"] - t0, 3),
                        "end_s": round(p["end"] - t0, 3)} for p in got["pass"]],
            "trucks": [{k: t[k] for k in keep_t} for t in got["truck"] if t.get("closed")]}


def check(capture: Path) -> list[str]:
    """Differences between a replay and the capture's expectation (empty: it passes)."""
    exp = json.loads((capture / "expected.json").read_text())
    got = replay(capture, float(exp["truck_target_kg"]))
    problems = []
    want = exp["passes"]
    if [(p["pass"], p["truck"], p["valid"]) for p in got["passes"]] != \
            [(p["pass"], p["truck"], p["valid"]) for p in want]:
        problems.append(f"passes differ: got {got['passes']}, expected {want}")
        return problems
    for g, w, truth, off in zip(got["passes"], want, exp["true_payload_kg"], exp["offline_kg"],
                                strict=True):
        if abs(g["payload_kg"] - w["payload_kg"]) > 1.0:
            problems.append(f"pass {g['pass']}: {g['payload_kg']} kg, expected "
                            f"{w['payload_kg']} kg (regression)")
        for ref, what in ((truth, "true payload"), (off, "offline estimate")):
            if abs(g["payload_kg"] - ref) > 0.01 * RATED_KG:
                problems.append(f"pass {g['pass']}: {g['payload_kg']} kg is more than 1 % of "
                                f"rated load from the {what} {ref} kg")
    if [(t["truck"], t["passes"], t["status"]) for t in got["trucks"]] != \
            [(t["truck"], t["passes"], t["status"]) for t in exp["trucks"]]:
        problems.append(f"trucks differ: got {got['trucks']}, expected {exp['trucks']}")
    return problems


def rebuild(capture: Path) -> None:
    path = capture / "expected.json"
    exp = json.loads(path.read_text())
    exp.update(replay(capture, float(exp["truck_target_kg"])))
    path.write_text(json.dumps(exp, indent=1) + "\n")


def captures() -> list[Path]:
    return sorted(p for p in CAPTURES.iterdir() if (p / "expected.json").exists())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rebuild", action="store_true")
    ap.add_argument("names", nargs="*", help="capture folder names (default: all)")
    args = ap.parse_args()
    failed = 0
    for cap in captures():
        if args.names and cap.name not in args.names:
            continue
        if args.rebuild:
            rebuild(cap)
            print(f"{cap.name}: rebuilt")
            continue
        problems = check(cap)
        failed += bool(problems)
        print(f"{cap.name}: {'ok' if not problems else 'FAILED'}")
        for p in problems:
            print(f"  {p}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
