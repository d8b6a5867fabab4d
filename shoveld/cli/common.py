"""Helpers shared by subcommands: reading tables and params with one-line errors.

The readers import numpy and the model when called, not when ``shoveld --help`` (which
imports every subcommand's module to list it) loads this file.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from shoveld.cli import CliError

if TYPE_CHECKING:
    from shoveld.model.params import ModelParams
    from shoveld.signals.table import SignalsTable


def read_tables(paths: list[str]) -> list[SignalsTable]:
    from shoveld.signals.table import SignalsFormatError, read_table

    out = []
    for p in paths:
        try:
            out.append(read_table(p))
        except SignalsFormatError as e:
            raise CliError(str(e)) from None
    return out


def read_params(path: str) -> ModelParams:
    from shoveld.model.params import ParamsFileError, load_params

    try:
        return load_params(path)
    except ParamsFileError as e:
        raise CliError(str(e)) from None


def parse_effects(text: str | None) -> list[str]:
    """'a,b' -> ['a', 'b'] (blank entries dropped)."""
    return [e.strip() for e in (text or "").split(",") if e.strip()]
