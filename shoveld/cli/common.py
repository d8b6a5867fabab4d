"""Helpers shared by subcommands: reading tables and params with one-line errors."""

from __future__ import annotations

from shoveld.cli import CliError
from shoveld.model.params import ModelParams, ParamsFileError, load_params
from shoveld.signals.table import SignalsFormatError, SignalsTable, read_table


def read_tables(paths: list[str]) -> list[SignalsTable]:
    out = []
    for p in paths:
        try:
            out.append(read_table(p))
        except SignalsFormatError as e:
            raise CliError(str(e)) from None
    return out


def read_params(path: str) -> ModelParams:
    try:
        return load_params(path)
    except ParamsFileError as e:
        raise CliError(str(e)) from None


def parse_effects(text: str | None) -> list[str]:
    """'a,b' -> ['a', 'b'] (blank entries dropped)."""
    return [e.strip() for e in (text or "").split(",") if e.strip()]
