"""pymodbus' register responses, refusing an odd byte count.

A read-registers answer carries a byte count and then 16-bit words; pymodbus decodes
an odd count by rounding it down, so a truncated or garbled answer can still give the
asked number of registers. Registered on the driver's client, these subclasses make
such an answer a decoding error (counted as a timeout-free bad answer by the driver).
"""

from __future__ import annotations

from typing import Any

from pymodbus.exceptions import ModbusIOException
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersResponse,
    ReadInputRegistersResponse,
)


def _strict(base: type[Any]) -> type[Any]:
    class Strict(base):
        def decode(self, data: bytes) -> None:
            if data and data[0] % 2:
                raise ModbusIOException(f"odd byte count {data[0]} in a register response",
                                        function_code=self.function_code)
            super().decode(data)

    Strict.__name__ = "Strict" + base.__name__
    return Strict


StrictInputRegisters = _strict(ReadInputRegistersResponse)
StrictHoldingRegisters = _strict(ReadHoldingRegistersResponse)


def strict_registers(decoder: Any) -> Any:
    """Register the strict responses on a pymodbus client (or a ``DecodePDU``)."""
    if hasattr(decoder, "register"):
        decoder.register(StrictInputRegisters)
        decoder.register(StrictHoldingRegisters)
    return decoder
