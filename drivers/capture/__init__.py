"""Captures: record what devices said, read it back, replay it through the real drivers.

See ``docs/captures.md`` for the folder format; :mod:`drivers.capture.replay`
for replay and :class:`drivers.capture.clock.ReplayClock` for the shared clock.
"""

from drivers.capture.clock import ReplayClock
from drivers.capture.format import (
    Capture,
    CaptureFormatError,
    CaptureWriter,
    RegisterRead,
    SerialChunk,
    read_capture,
)

__all__ = ["Capture", "CaptureFormatError", "CaptureWriter", "RegisterRead", "ReplayClock",
           "SerialChunk", "read_capture"]
