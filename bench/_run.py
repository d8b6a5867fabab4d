"""What the accuracy benches share: run the cases on worker processes, keep them."""

from __future__ import annotations

import json
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np


def run_cases(one: Callable[[dict[str, Any]], dict[str, Any]], jobs: list[dict[str, Any]],
              workers: int, json_path: str | None) -> list[dict[str, Any]]:
    """``one`` over ``jobs`` on ``workers`` processes, in order; every case written to
    ``json_path`` (JSON lines) when given."""
    with ProcessPoolExecutor(workers) as ex:
        results = list(ex.map(one, jobs))
    if json_path:
        with open(json_path, "w") as f:
            for r in results:
                f.write(json.dumps(r) + "\n")
    return results


def model_error(e: np.ndarray, a: np.ndarray) -> float:
    """The type B u that makes the RMS of e / sqrt(a^2 + u^2) one (0 if the standard
    errors ``a`` already cover the errors ``e``): bisection, the RMS falls with u."""
    def rms_z(u: float) -> float:
        return float(np.sqrt(np.mean(e**2 / (a**2 + u**2))))

    if rms_z(0.0) <= 1.0:
        return 0.0
    lo, hi = 0.0, float(np.abs(e).max()) + 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if rms_z(mid) > 1.0 else (lo, mid)
    return 0.5 * (lo + hi)
