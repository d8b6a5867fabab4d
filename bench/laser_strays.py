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
the clean capture's: the pass error in kilograms, and the passes lost (the capture
has three).

    .venv/bin/python bench/laser_strays.py [--rates 0.005,0.02,0.05] [--seeds 10]
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
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CAPTURE = ROOT / "hil_fixtures" / "captures" / "daemon-e2e"
PARAMS = CAPTURE / "params.toml"


def stray_capture(dst: Path, rate: float, seed: int, rule: bool) -> Path:
    """A copy of the capture with stray returns in the laser's lines (and the rule off
    in its laser config if not ``rule``)."""
    shutil.copytree(CAPTURE, dst)
    rng = random.Random(seed)
    src = (CAPTURE / "laser.serial.jsonl").read_text().splitlines()
    out, line = [src[0]], []  # header; the chunks of the line being received
    for text in src[1:]:
        rec = json.loads(text)
        if rec["d"] != "rx":
            out.append(text)
            continue
        line.append(rec)
        data = bytes.fromhex(rec["hex"])
        if not data.endswith(b"\n"):
            continue
        whole = b"".join(bytes.fromhex(r["hex"]) for r in line)
        digits = whole.strip()
        if rate and digits.isdigit() and int(digits) and rng.random() < rate:
            mm = int(digits) + rng.choice((-1, 1)) * rng.randint(500, 3000)
            new = f"{max(100, mm)}\r\n".encode()
            line = [{**line[0], "hex": new.hex()}]  # the whole line at its first byte's time
        out.extend(json.dumps(r, separators=(",", ":")) for r in line)
        line = []
    out.extend(json.dumps(r, separators=(",", ":")) for r in line)
    (dst / "laser.serial.jsonl").write_text("\n".join(out) + "\n")
    if not rule:
        man = json.loads((dst / "manifest.json").read_text())
        man["devices"]["laser"]["config"]["max_speed_mps"] = 1e9
        (dst / "manifest.json").write_text(json.dumps(man, indent=2))
    return dst


def replay(capture: Path) -> dict[str, Any]:
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
    return {"passes": [(m["pass"], m["payload_kg"] if m.get("valid") else None)
                       for m in passes],
            "jumps": laser.get("jumps", 0)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rates", default="0.005,0.02,0.05")
    ap.add_argument("--seeds", type=int, default=10)
    args = ap.parse_args()
    logging.disable(logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        clean = dict(replay(CAPTURE)["passes"])
        print(f"clean capture: passes {[round(v, 1) for v in clean.values()]} kg")
        print(f"{'rate':>6s} {'rule':>4s} {'passes':>7s} {'lost':>5s} {'|err| median':>13s} "
              f"{'p90':>8s} {'max':>8s} {'jumps/run':>10s}")
        for rate in (float(x) for x in args.rates.split(",")):
            for rule in (True, False):
                errs: list[float] = []
                lost = jumps = 0
                for seed in range(1, args.seeds + 1):
                    cap = stray_capture(Path(tmp) / f"r{rate}-{rule}-{seed}", rate, seed, rule)
                    got = replay(cap)
                    jumps += got["jumps"]
                    have = dict(got["passes"])
                    for no, kg in clean.items():
                        if no in have and have[no] is not None:
                            errs.append(abs(have[no] - kg))
                        else:
                            lost += 1
                    shutil.rmtree(cap)
                errs.sort()
                med = statistics.median(errs) if errs else float("nan")
                p90 = errs[int(0.9 * (len(errs) - 1))] if errs else float("nan")
                top = errs[-1] if errs else float("nan")
                print(f"{rate:6.3f} {'on' if rule else 'off':>4s} {len(errs):7d} {lost:5d} "
                      f"{med:10.1f} kg {p90:5.0f} kg {top:5.0f} kg {jumps / args.seeds:10.1f}",
                      flush=True)


if __name__ == "__main__":
    main()
