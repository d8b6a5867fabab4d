"""Acuity laser distance sensors (AccuRange AR4000)."""

from drivers.acuity.ar4000 import Ar4000Config, Ar4000Driver, LineSplitter, parse_line

__all__ = ["Ar4000Config", "Ar4000Driver", "LineSplitter", "parse_line"]
