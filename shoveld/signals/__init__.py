"""Signals tables: the project's measured-data format (``docs/signals-format.md``)."""

from shoveld.signals.columns import COLUMN_NAMES, COLUMNS, FORMAT_NAME
from shoveld.signals.table import SignalsFormatError, SignalsTable, read_table, write_table

__all__ = ["COLUMNS", "COLUMN_NAMES", "FORMAT_NAME", "SignalsFormatError", "SignalsTable",
           "read_table", "write_table"]
