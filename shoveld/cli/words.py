"""Words a person reads in the commands' output ("1 pass", "2 passes")."""

from __future__ import annotations

from typing import Any


def n_of(k: Any, one: str, many: str) -> str:
    """``k`` with the singular or plural noun, as a person would write it."""
    return f"{k} {one if k == 1 else many}"
