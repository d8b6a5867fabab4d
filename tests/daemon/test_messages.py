"""The loop's messages written directly as JSON text equal ``dumps`` of their dicts."""

from __future__ import annotations

import json
import math
import random
from types import SimpleNamespace
from typing import Any

from shoveld.daemon.publisher import dumps
from shoveld.daemon.service import Service, _r, joints_json
from shoveld.sample import Sample

SPECIAL = [math.nan, math.inf, -math.inf, 0.0, -0.0, 1e-9, 123456789.123456, -3.0005,
           2.675, 1e20]


def joints_dict(wall: float, s: Sample) -> dict[str, Any]:
    bad = s.invalid
    return {"time": round(wall, 3),
            "swing_deg": None if "swing_deg" in bad else _r(s.swing_deg, 3),
            "handle_deg": None if "handle_deg" in bad else _r(s.handle_deg, 3),
            "crowd_m": None if "crowd_m" in bad else _r(s.crowd_m, 4),
            "boom_deg": None if "boom_deg" in bad else _r(s.boom_deg, 3),
            "invalid": sorted(bad)}


def value(rng: random.Random) -> float:
    return rng.choice(SPECIAL) if rng.random() < 0.3 else rng.uniform(-1e4, 1e4)


def test_joints_text_is_dumps_of_the_dict() -> None:
    rng = random.Random(1)
    names = ["swing_deg", "handle_deg", "crowd_m", "boom_deg", "hoist1_a", 'we"ird\u00e9']
    for _ in range(3000):
        s = Sample(rng.uniform(0, 1e5), handle_deg=value(rng), crowd_m=value(rng),
                   swing_deg=value(rng), boom_deg=value(rng),
                   invalid=frozenset(n for n in names if rng.random() < 0.2))
        wall = 1.7e9 + rng.uniform(0, 1e6)
        text = joints_json(wall, s)
        assert text == dumps(joints_dict(wall, s))
        json.loads(text)


def test_live_text_is_dumps_of_the_live_message() -> None:
    rng = random.Random(2)
    svc = Service.__new__(Service)  # only the live-message builders are used
    svc.clock = SimpleNamespace(wall=lambda t: 1.7e9 + t)
    svc._live_built = None
    for _ in range(3000):
        ev = SimpleNamespace(time_s=rng.uniform(0, 1e5), payload_kg=value(rng),
                             std_kg=value(rng), valid=rng.random() < 0.7,
                             phase=rng.choice(["dig", "swing_loaded", "dump", 'x"y']))
        doubt = rng.choice([None, "had no reading for 1.0 s", "took another target", 'q"\u00e9'])
        svc._live = (ev, rng.randrange(1, 500), rng.randrange(1, 100),  # type: ignore[assignment]
                     doubt)
        assert svc.live_json() == dumps(svc.live_msg)
