"""Xsens MTi drivers: Xbus serial (any MTi) and CAN (MTi-600 series).

Protocol modules are imported eagerly (pure Python, no I/O); the two driver classes
are imported on first use so that decoding captures does not pull in pyserial or
python-can::

    from drivers.xsens import MtiSerialDriver, MtiCanDriver, XbusParser, decode_mtdata2

See docs/drivers-xsens.md for what is implemented and which vendor documents back it.
"""

from __future__ import annotations

from typing import Any

from drivers.xsens.mtdata2 import (
    XDI,
    DataItem,
    decode_mtdata2,
    encode_item,
    encode_mtdata2,
    mtdata2_values,
)
from drivers.xsens.xbus import MID, XbusMessage, XbusParser, encode_frame

__all__ = ["MID", "XDI", "DataItem", "MtiCanDriver", "MtiSerialDriver", "XbusMessage",
           "XbusParser", "decode_mtdata2", "encode_frame", "encode_item", "encode_mtdata2",
           "mtdata2_values"]


def __getattr__(name: str) -> Any:
    if name == "MtiSerialDriver":
        from drivers.xsens.serial_driver import MtiSerialDriver
        return MtiSerialDriver
    if name == "MtiCanDriver":
        from drivers.xsens.can_driver import MtiCanDriver
        return MtiCanDriver
    raise AttributeError(f"module 'drivers.xsens' has no attribute {name!r}")
