"""What something else in the laser's beam does to the payload, with and without the
driver's jump rule.

A laser on a shovel's saddle block sees dust, rain, a hoist rope or the boom between it
and the target on the handle: a well-formed line, a distance 0.5-3 m off (the
emulator's ``stray``). The AR4000 protocol has no checksum, so before 2026-11-29 the
driver used every such line as the crowd extension. This bench writes such returns
into a copy of the committed capture's laser stream (each line, with probability
``rate``, replaced by the target's distance +- 0.5-3 m, at the same moment) and
replays it fast through the daemon's own code (``fast_replay_service``: the drivers,
the loop, the estimator), with the driver's rule (the default) and without it
(``max_speed_mps = 1e9`` in the capture's laser config). Each pass is compared with
the clean capture's: the pass error in kilograms of the passes weighed, the passes
published not weighed, and the passes lost (the capture has three); and of the passes
weighed more than a tonne off, and of those within a tonne, how many the daemon warned
of for their misfit (above ``engine.misfit_warn``: weighed all the same, but not
silently).

``--blocks`` puts something in the beam that stays: in each pass, once, for a given
time (a rope swinging through, a dust cloud that hangs), every line is a return 0.5-3
m off the target (the same offset for the whole block, +-2 mm), its middle at a random
time of the pass's lift and swing (the pass's last ``samples`` ticks before the dump),
where the payload is estimated. ``--other-target-s`` sets how long the driver refuses
such a thing before it takes it as the target; ``--in-passes`` puts blocks in some
passes only, to see what a block costs the passes around it (the engine does not weigh
a pass across which, from its dig's start to its dump, the laser changed target).

    .venv/bin/python bench/laser_strays.py [--rates 0.005,0.02,0.05] [--seeds 10]
    .venv/bin/python bench/laser_strays.py --blocks 0.1,0.3,1,3,10 [--seeds 10]
        [--other-target-s 2] [--in-passes 2]
    .venv/bin/python bench/laser_strays.py --lodged [--seeds 10]
    .venv/bin/python bench/laser_strays.py --outages 0.3,1,2,5 [--seeds 10]

``--outages`` cuts the laser's stream in pass 2's lift and swing (the driver goes silent
after ``silent_timeout_s`` and reconnects) and puts something on the handle, moving with
it, from the cut to the end: the pass of the outage and the next are at stake.
"""

from __future__ import annotations

import argparse
import json
import logging
import random
import shutil
import statistics
import tempfile
import threading
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CAPTURE = ROOT / "hil_fixtures" / "captures" / "daemon-e2e"
PARAMS = CAPTURE / "params.toml"
TICK_S = 0.01
"""The loop's tick (100 Hz): a pass's lift and swing are about its last ``samples``
ticks before the dump."""


Blocks = list[tuple[float, float, int]]
"""Something in the beam: (from, to) in capture seconds, and its offset from the target
in mm."""


def stray_capture(dst: Path, rate: float, seed: int, rule: bool,
                  blocks: Blocks | None = None, laser: dict[str, Any] | None = None,
                  lodged: tuple[float, int] | None = None,
                  outage: tuple[float, float] | None = None) -> Path:
    """A copy of the capture with stray returns in the laser's lines, and lines inside
    ``blocks`` off by the block's offset (and the rule off in its laser config if not
    ``rule``); with ``lodged`` (from, offset in mm), every line from then on reads one
    distance, the handle's then plus the offset: something lodged in the beam; with
    ``outage`` (from, to), nothing the laser sent in between reaches the host (a cable
    pulled, the device's power lost: the driver goes silent and reconnects)."""
    shutil.copytree(CAPTURE, dst)
    rng = random.Random(seed)
    src = (CAPTURE / "laser.serial.jsonl").read_text().splitlines()
    out, line = [src[0]], []  # header; the chunks of the line being received
    still: int | None = None  # the lodged thing's distance, once it is there
    for text in src[1:]:
        rec = json.loads(text)
        if rec["d"] != "rx":
            out.append(text)
            continue
        if outage is not None and outage[0] <= rec["t"] < outage[1]:
            continue
        line.append(rec)
        data = bytes.fromhex(rec["hex"])
        if not data.endswith(b"\n"):
            continue
        whole = b"".join(bytes.fromhex(r["hex"]) for r in line)
        t = line[0]["t"]
        block = next((off for a, b, off in blocks or () if a <= t < b), None)
        texts: list[bytes] = []  # a chunk may end more than one line
        changed = False
        for raw in whole.split(b"\n")[:-1]:
            digits = raw.strip()
            mm = None
            if lodged is not None and t >= lodged[0] and digits.isdigit():
                if still is None and int(digits):
                    still = int(digits) + lodged[1]
                if still is not None:
                    mm = still + rng.randint(-2, 2)
            elif digits.isdigit() and int(digits):
                if block is not None:
                    mm = int(digits) + block + rng.randint(-2, 2)
                elif rate and rng.random() < rate:
                    mm = int(digits) + rng.choice((-1, 1)) * rng.randint(500, 3000)
            changed |= mm is not None
            texts.append(raw if mm is None else f"{max(100, mm)}\r".encode())
        if changed:  # the whole chunk at its first byte's time
            line = [{**line[0], "hex": (b"\n".join(texts) + b"\n").hex()}]
        out.extend(json.dumps(r, separators=(",", ":")) for r in line)
        line = []
    out.extend(json.dumps(r, separators=(",", ":")) for r in line)
    (dst / "laser.serial.jsonl").write_text("\n".join(out) + "\n")
    config = {**(laser or {}), **({} if rule else {"max_speed_mps": 1e9})}
    if config:
        man = json.loads((dst / "manifest.json").read_text())
        man["devices"]["laser"]["config"].update(config)
        (dst / "manifest.json").write_text(json.dumps(man, indent=2))
    return dst


def replay(capture: Path) -> dict[str, Any]:
    """The capture replayed fast through the daemon: its passes (payload, None if not
    weighed), each pass's lift and swing in capture seconds (``spans``), the reasons of
    those not weighed, and the laser's jumps."""
    from shoveld.daemon.config import parse_config
    from shoveld.model.params import load_params
    from shoveld.replay.service import fast_replay_service

    with tempfile.TemporaryDirectory() as tmp:
        cfg = parse_config({"shovel": {"id": "bench", "params": str(PARAMS), "state_dir": tmp},
                            "zenoh": {"listen": []}, "truck": {"target_kg": 62000.0}},
                           require_devices=False)
        rr = fast_replay_service(capture, cfg, load_params(PARAMS), bulk=True)
        svc = rr.service
        passes: list[dict[str, Any]] = []
        svc.on_event = lambda k, m: passes.append(m) if k == "pass" else None
        try:
            svc.start(zenoh_wait_s=5.0)
            rr.run(threading.Event())
            svc.flush()
            laser = svc.drivers["laser"].health.extra
        finally:
            rr.close()
    start = json.loads((capture / "manifest.json").read_text())["start_unix"]
    return {"passes": [(m["pass"], m["payload_kg"] if m.get("valid") else None)
                       for m in passes],
            "spans": [(m["pass"], m["end"] - m["samples"] * TICK_S - start, m["end"] - start)
                      for m in passes],
            "reasons": {m["pass"]: m.get("reason", "") for m in passes if not m.get("valid")},
            "misfits": {m["pass"]: m.get("misfit") for m in passes},
            "jumps": laser.get("jumps", 0)}


def pass_blocks(spans: list[tuple[int, float, float]], duration: float,
                rng: random.Random, only: set[int] | None = None) -> Blocks:
    """One block of ``duration`` s in each pass (or in the passes numbered in ``only``),
    its middle at a random time of the pass's lift and swing (where the payload is
    estimated; ``spans``)."""
    out: Blocks = []
    for no, a, b in spans:
        if only is not None and no not in only:
            continue
        t0 = rng.uniform(a, b) - duration / 2
        out.append((t0, t0 + duration, rng.choice((-1, 1)) * rng.randint(500, 3000)))
    return out


def summary(errs: list[float]) -> tuple[float, float, float]:
    """Median, p90 and largest of the errors (nan where there are none)."""
    errs = sorted(errs)
    if not errs:
        return float("nan"), float("nan"), float("nan")
    return statistics.median(errs), errs[int(0.9 * (len(errs) - 1))], errs[-1]


def print_header(clean: dict[int, float], first: str, note: str = "") -> None:
    print(f"clean capture: passes {[round(v, 1) for v in clean.values()]} kg{note}")
    print(f"{first:>6s} {'rule':>4s} {'weighed':>7s} {'not':>4s} {'lost':>5s} "
          f"{'|err| median':>13s} {'p90':>8s} {'max':>8s} {'jumps/run':>10s} "
          f"{'misfit warned: >1 t off':>24s} {'<=1 t off':>10s}")


def print_row(label: str, rule: bool, clean: dict[int, float], seeds: int,
              make: Callable[[int], Path]) -> None:
    """One row of the table: the capture ``make(seed)`` gives for each seed, replayed,
    its passes against the clean capture's: the errors of those weighed, and how many
    were published not weighed ("not") and not published at all ("lost"); and of those
    weighed more than a tonne off, how many the daemon warned of for their misfit."""
    from shoveld.payload.misfit import misfit_high

    errs: list[float] = []
    not_weighed = lost = jumps = off = warned = near_warned = 0
    for seed in range(1, seeds + 1):
        cap = make(seed)
        got = replay(cap)
        jumps += got["jumps"]
        have = dict(got["passes"])
        for no, kg in clean.items():
            if no not in have:
                lost += 1
            elif have[no] is None:
                not_weighed += 1
            else:
                errs.append(abs(have[no] - kg))
                high = misfit_high(got["misfits"][no])
                if errs[-1] > 1000.0:
                    off += 1
                    warned += high
                else:
                    near_warned += high
        shutil.rmtree(cap)
    med, p90, top = summary(errs)
    print(f"{label} {'on' if rule else 'off':>4s} {len(errs):7d} {not_weighed:4d} {lost:5d} "
          f"{med:10.1f} kg {p90:5.0f} kg {top:5.0f} kg {jumps / seeds:10.1f} "
          f"{f'{warned} of {off}':>24s} {f'{near_warned} of {len(errs) - off}':>10s}",
          flush=True)


def run_rates(rates: list[float], seeds: int, tmp: Path) -> None:
    """Stray lines, each line with probability ``rate``."""
    clean = dict(replay(CAPTURE)["passes"])
    print_header(clean, "rate")

    def make(seed: int, rate: float, rule: bool) -> Path:
        return stray_capture(tmp / f"r{rate}-{rule}-{seed}", rate, seed, rule)

    for rate in rates:
        for rule in (True, False):
            print_row(f"{rate:6.3f}", rule, clean, seeds, partial(make, rate=rate, rule=rule))


def run_blocks(durations: list[float], seeds: int, tmp: Path,
               laser: dict[str, Any] | None = None, only: set[int] | None = None) -> None:
    """Something that stays in the beam, once a pass (of those in ``only``), for each of
    ``durations``."""
    base = replay(CAPTURE)
    clean = dict(base["passes"])
    print_header(clean, "block", "; one block a pass" if only is None else
                 f"; one block in pass {', '.join(map(str, sorted(only)))}")

    def make(seed: int, dur: float, rule: bool) -> Path:
        blocks = pass_blocks(base["spans"], dur, random.Random(seed), only)
        return stray_capture(tmp / f"b{dur}-{rule}-{seed}", 0.0, seed, rule, blocks, laser)

    for dur in durations:
        for rule in (True, False):
            print_row(f"{dur:5.2f}s", rule, clean, seeds, partial(make, dur=dur, rule=rule))


def run_lodged(seeds: int, tmp: Path) -> None:
    """Something lodged in the beam in the return after pass 1, there to the end."""
    base = replay(CAPTURE)
    clean = dict(base["passes"])
    print_header(clean, "lodged", "; something lodged in the beam after pass 1's dump")
    end1 = base["spans"][0][2]

    def make(seed: int, rule: bool) -> Path:
        rng = random.Random(seed)
        lodged = (end1 + rng.uniform(0.5, 3.0), rng.choice((-1, 1)) * rng.randint(500, 3000))
        return stray_capture(tmp / f"l{rule}-{seed}", 0.0, seed, rule, lodged=lodged)

    for rule in (True, False):
        print_row(f"{'':>6s}", rule, clean, seeds, partial(make, rule=rule))


def run_outages(gaps: list[float], seeds: int, tmp: Path) -> None:
    """The laser's stream cut for ``gap`` seconds in pass 2's lift and swing, and
    something on the handle (moving with it, 0.5-3 m off the target) in the beam from
    the cut to the end: it came while the port was down."""
    base = replay(CAPTURE)
    clean = dict(base["passes"])
    print_header(clean, "outage", "; an outage in pass 2, something on the handle after it")
    _, a, b = base["spans"][1]
    end = base["spans"][-1][2] + 100.0

    def make(seed: int, gap: float) -> Path:
        rng = random.Random(seed)
        t0 = rng.uniform(a, max(a, b - gap))
        off = rng.choice((-1, 1)) * rng.randint(500, 3000)
        return stray_capture(tmp / f"o{gap}-{seed}", 0.0, seed, True,
                             blocks=[(t0, end, off)], outage=(t0, t0 + gap))

    for gap in gaps:
        print_row(f"{gap:5.1f}s", True, clean, seeds, partial(make, gap=gap))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rates", default="0.005,0.02,0.05")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--blocks", default="", metavar="S,S,...",
                    help="something that stays in the beam: one block a pass of each of "
                         "these durations (seconds), instead of stray lines")
    ap.add_argument("--other-target-s", type=float, default=None,
                    help="the laser driver's other_target_s for --blocks (default: its own)")
    ap.add_argument("--lodged", action="store_true",
                    help="something lodged in the beam after pass 1's dump, to the end")
    ap.add_argument("--in-passes", default="", metavar="N,N,...",
                    help="--blocks only in these passes (default: every pass), to see "
                         "what a block costs the passes around it")
    ap.add_argument("--outages", default="", metavar="S,S,...",
                    help="the laser's stream cut for each of these times (seconds) in "
                         "pass 2, something on the handle after it")
    args = ap.parse_args()
    logging.disable(logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        if args.outages:
            run_outages([float(x) for x in args.outages.split(",")], args.seeds, Path(tmp))
        elif args.lodged:
            run_lodged(args.seeds, Path(tmp))
        elif args.blocks:
            run_blocks([float(x) for x in args.blocks.split(",")], args.seeds, Path(tmp),
                       {"other_target_s": args.other_target_s} if args.other_target_s
                       else None,
                       {int(x) for x in args.in_passes.split(",")} if args.in_passes
                       else None)
        else:
            run_rates([float(x) for x in args.rates.split(",")], args.seeds, Path(tmp))


if __name__ == "__main__":
    main()
