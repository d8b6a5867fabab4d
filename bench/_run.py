"""What the accuracy benches share: run the cases on worker processes, keep them."""

from __future__ import annotations

import json
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any


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
