"""Xsens MTi-600 series driver over CAN (python-can; any interface from config).

The MTi-600 CAN output is one frame per quantity, the CAN id being the data
identifier (``XsCanDataIdentifier`` in the vendor SDK, xscandataidentifier.h). The
defaults below:

=================  ======  =======================  ==================================
message            id      payload                  scaling (configurable)
=================  ======  =======================  ==================================
Error              0x001   uint8 code               0x01 = output buffer overflow
SampleTime         0x005   uint32                   10 kHz ticks (1e-4 s)
GroupCounter       0x006   uint16                   +1 per output group
StatusWord         0x011   uint32                   as XDI_StatusWord
Quaternion         0x021   4 x int16 q0..q3         2^-15
EulerAngles        0x022   3 x int16 roll/pitch/yaw 2^-7 deg
RateOfTurn         0x032   3 x int16 x/y/z          2^-9 rad/s
Acceleration       0x034   3 x int16 x/y/z          2^-8 m/s^2
=================  ======  =======================  ==================================

Sources: the ids are the vendor SDK enum and the Movella "CAN Messages" page (which
documents 0x001, 0x005, 0x006 and says SampleTime counts 10 kHz ticks). The int16
scalings and the big-endian (Motorola) byte order are those of the Xsens CAN database
``xsens.dbc`` (a copy in a public repository; Movella says the .dbc is published on
Xsens BASE, which I could not reach) and agree with public notes citing the MT CAN
Protocol Documentation (MT1604P), which I could not read. The same .dbc gives the
SampleTime unit as "us", contradicting the Movella page: hence
``sample_time_scale_s`` (default 1e-4, the page's and SampleTimeFine's 10 kHz). All
scalings and the byte order stay configurable (:class:`MtiCanLayout`).
CAN output is configured over Xbus (SetCanOutputConfig), not over CAN, so this driver
only listens; ``open()`` succeeds once an MTi frame arrives. It assembles the frames of
one output group and emits a :class:`Reading` when every configured message of the
group has arrived (or, if a frame is lost, when the next group starts, with the missing
quantities invalid).
"""

from __future__ import annotations

import logging
import struct
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import can

from drivers.base import DeviceError, Driver, Reading, Sink, check_keys
from drivers.xsens.orientation import quat_to_euler_deg

log = logging.getLogger(__name__)

KINDS = ("error", "sample_time", "group_counter", "status_word", "quaternion", "euler_angles",
         "rate_of_turn", "acceleration")
DEFAULT_MESSAGES = ("sample_time", "group_counter", "status_word", "euler_angles",
                    "rate_of_turn", "acceleration")
_QUANTITIES = {
    "sample_time": ("sample_time_fine",), "group_counter": ("packet_counter",),
    "status_word": ("status_word",), "euler_angles": ("roll_deg", "pitch_deg", "yaw_deg"),
    "quaternion": ("roll_deg", "pitch_deg", "yaw_deg"),
    "rate_of_turn": ("gyr_x", "gyr_y", "gyr_z"), "acceleration": ("acc_x", "acc_y", "acc_z"),
}


_SIZES = {"euler_angles": 6, "rate_of_turn": 6, "acceleration": 6, "quaternion": 8,
          "sample_time": 4, "status_word": 4, "group_counter": 2, "error": 1}
"""Data bytes of each MTi CAN message (int16 triples/quads, u32, u16, one byte)."""


@dataclass(frozen=True)
class MtiCanLayout:
    """CAN ids, scalings and byte order of the MTi CAN output (defaults: MTi-600)."""

    error_id: int = 0x001
    sample_time_id: int = 0x005
    group_counter_id: int = 0x006
    status_word_id: int = 0x011
    quaternion_id: int = 0x021
    euler_angles_id: int = 0x022
    rate_of_turn_id: int = 0x032
    acceleration_id: int = 0x034
    extended_id: bool = False
    quaternion_scale: float = 2.0 ** -15
    euler_scale_deg: float = 2.0 ** -7
    rate_of_turn_scale: float = 2.0 ** -9
    acceleration_scale: float = 2.0 ** -8
    sample_time_scale_s: float = 1e-4
    byteorder: str = "big"

    def __post_init__(self) -> None:
        if self.byteorder not in ("big", "little"):
            raise ValueError(f"mti_can config: 'byteorder' must be 'big' or 'little', "
                             f"got {self.byteorder!r}")
        limit = 0x1FFFFFFF if self.extended_id else 0x7FF
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name.endswith("_id") and f.name != "extended_id":
                if not (isinstance(v, int) and 0 <= v <= limit):
                    raise ValueError(f"mti_can config: '{f.name}' must be a CAN id in "
                                     f"0..0x{limit:X}, got {v!r}")
            elif f.name.endswith(("_scale", "_scale_s", "_scale_deg")):
                if not (isinstance(v, (int, float)) and v > 0):
                    raise ValueError(f"mti_can config: '{f.name}' must be > 0, got {v!r}")
        ids = [getattr(self, f"{k}_id") for k in KINDS]
        if len(set(ids)) != len(ids):
            raise ValueError("mti_can config: two messages share one CAN id")

    def id_of(self, kind: str) -> int:
        return int(getattr(self, f"{kind}_id"))


class MtiCanCodec:
    """Encode/decode MTi CAN frames for one :class:`MtiCanLayout` (driver and emulator)."""

    def __init__(self, layout: MtiCanLayout | None = None) -> None:
        self.layout = layout or MtiCanLayout()
        lay = self.layout
        e = ">" if lay.byteorder == "big" else "<"
        self._s3 = struct.Struct(e + "3h")
        self._s4 = struct.Struct(e + "4h")
        self._u32 = struct.Struct(e + "I")
        self._u16 = struct.Struct(e + "H")
        self._kind_of = {lay.id_of(k): k for k in KINDS}
        self._scale = {"quaternion": lay.quaternion_scale, "euler_angles": lay.euler_scale_deg,
                       "rate_of_turn": lay.rate_of_turn_scale,
                       "acceleration": lay.acceleration_scale}

    @property
    def ids(self) -> list[int]:
        return sorted(self._kind_of)

    def decode(self, arbitration_id: int, data: bytes) -> tuple[str, tuple[float, ...]] | None:
        """(kind, values) of one frame; None for a foreign id or a too-short payload."""
        kind = self._kind_of.get(arbitration_id)
        if kind is None or len(data) != _SIZES.get(kind, len(data)):
            return None  # a frame of the wrong length is not this message
        try:
            if kind in ("euler_angles", "rate_of_turn", "acceleration"):
                sc = self._scale[kind]
                return kind, tuple(v * sc for v in self._s3.unpack_from(data))
            if kind == "quaternion":
                sc = self._scale[kind]
                return kind, tuple(v * sc for v in self._s4.unpack_from(data))
            if kind in ("sample_time", "status_word"):
                return kind, (float(self._u32.unpack_from(data)[0]),)
            if kind == "group_counter":
                return kind, (float(self._u16.unpack_from(data)[0]),)
            return kind, (float(data[0]),)
        except (struct.error, IndexError):
            return None

    def encode(self, kind: str, values: tuple[float, ...] | float) -> can.Message:
        """One frame; scaled values are rounded and saturated to int16."""
        vals = values if isinstance(values, tuple) else (values,)
        if kind in self._scale:
            sc = self._scale[kind]
            raw = [max(-32768, min(32767, round(v / sc))) for v in vals]
            data = (self._s4 if kind == "quaternion" else self._s3).pack(*raw)
        elif kind in ("sample_time", "status_word"):
            data = self._u32.pack(int(vals[0]) & 0xFFFFFFFF)
        elif kind == "group_counter":
            data = self._u16.pack(int(vals[0]) & 0xFFFF)
        elif kind == "error":
            data = bytes((int(vals[0]) & 0xFF,))
        else:
            raise ValueError(f"unknown MTi CAN message kind {kind!r}")
        return can.Message(arbitration_id=self.layout.id_of(kind), data=data,
                           is_extended_id=self.layout.extended_id)


class MtiCanDriver(Driver):
    """An MTi-600 on a CAN bus; emits the same Reading keys as the serial driver."""

    CONFIG_KEYS: tuple[str, ...] = (
        "name", "interface", "channel", "bitrate", "messages", "data_timeout_s",
        "recv_timeout_s", "backoff_s", *(f.name for f in fields(MtiCanLayout)))

    def __init__(self, name: str = "mti_can", channel: str = "can0",
                 interface: str = "socketcan", bitrate: int | None = None,
                 layout: MtiCanLayout | None = None,
                 messages: tuple[str, ...] = DEFAULT_MESSAGES, data_timeout_s: float = 1.0,
                 recv_timeout_s: float = 0.05, clock: Callable[[], float] = time.monotonic,
                 backoff_s: tuple[float, float] = (0.2, 5.0),
                 bus_factory: Callable[..., can.BusABC] = can.Bus,
                 timeout_clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(name, clock=clock, backoff_s=backoff_s)
        self.timeout_clock = timeout_clock
        """The clock ``data_timeout_s`` runs on once open: host time live; a replay stepped
        by its loop passes its capture clock, so a recorded silence is judged in capture
        time and the host's speed cannot change the outcome."""
        bad = [m for m in messages if m not in _QUANTITIES]
        if bad or not messages:
            raise ValueError(f"mti_can config: 'messages' must be a non-empty list of "
                             f"{sorted(_QUANTITIES)}, got {list(messages)!r}")
        if "euler_angles" in messages and "quaternion" in messages:
            raise ValueError("mti_can config: 'messages' takes euler_angles or quaternion, "
                             "not both")
        for key, v in (("data_timeout_s", data_timeout_s), ("recv_timeout_s", recv_timeout_s)):
            if not (isinstance(v, (int, float)) and 0 < v <= 60):
                raise ValueError(f"mti_can config: '{key}' must be seconds in (0, 60], "
                                 f"got {v!r}")
        if bitrate is not None and not (isinstance(bitrate, int) and bitrate > 0):
            raise ValueError(f"mti_can config: 'bitrate' must be a positive integer, "
                             f"got {bitrate!r}")
        self.channel = channel
        self.interface = interface
        self.bitrate = bitrate
        self.codec = MtiCanCodec(layout)
        self.messages = tuple(messages)
        self.data_timeout_s = float(data_timeout_s)
        self.recv_timeout_s = float(recv_timeout_s)
        self.bus_factory = bus_factory
        self._bus: can.BusABC | None = None
        self._first: can.Message | None = None
        self._group: dict[str, tuple[float, ...]] = {}
        self._group_t = 0.0
        self._prev_counter: int | None = None
        self._last_valid = 0.0
        self._expected = frozenset(q for m in self.messages for q in _QUANTITIES[m])
        self.health.extra.setdefault("dropped_packets", 0)
        self.health.extra.setdefault("device_errors", 0)
        self.health.extra.setdefault("incomplete_groups", 0)

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], **kwargs: Any) -> MtiCanDriver:
        """Build from a config mapping (ids may be ints or hex strings such as "0x022")."""
        check_keys("mti_can config", cfg, cls.CONFIG_KEYS)
        args = dict(cfg)
        layout_args: dict[str, Any] = {}
        for f in fields(MtiCanLayout):
            if f.name in args:
                v = args.pop(f.name)
                if f.name.endswith("_id") and f.name != "extended_id" and isinstance(v, str):
                    try:
                        v = int(v, 0)
                    except ValueError:
                        raise ValueError(f"mti_can config: '{f.name}' must be a CAN id, "
                                         f"got {v!r}") from None
                layout_args[f.name] = v
        if "messages" in args:
            m = args["messages"]
            if isinstance(m, str) or not isinstance(m, (list, tuple)):
                raise ValueError(f"mti_can config: 'messages' must be a list, got {m!r}")
            args["messages"] = tuple(m)
        if "backoff_s" in args:
            b = args["backoff_s"]
            if not (isinstance(b, (list, tuple)) and len(b) == 2 and 0 < b[0] <= b[1]):
                raise ValueError(f"mti_can config: 'backoff_s' must be [initial, maximum] "
                                 f"seconds, got {b!r}")
            args["backoff_s"] = (float(b[0]), float(b[1]))
        layout = replace(MtiCanLayout(), **layout_args)
        return cls(layout=layout, **args, **kwargs)

    def open(self) -> None:
        self.close()
        kw: dict[str, Any] = {"interface": self.interface, "channel": self.channel,
                              "can_filters": [{"can_id": i, "can_mask": 0x1FFFFFFF,
                                               "extended": self.codec.layout.extended_id}
                                              for i in self.codec.ids]}
        if self.bitrate is not None:
            kw["bitrate"] = self.bitrate
        try:
            self._bus = self.bus_factory(**kw)
        except (OSError, can.CanError, ValueError) as e:
            raise DeviceError(f"cannot open CAN {self.interface}:{self.channel} for the MTi: "
                              f"{e}") from e
        self._group = {}
        self._prev_counter = None
        # Connected means the MTi is talking, not just that the bus opened: wait for it.
        deadline = time.monotonic() + self.data_timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self.close()
                raise DeviceError(f"no MTi frames on CAN {self.interface}:{self.channel} "
                                  f"within {self.data_timeout_s:g} s of opening")
            try:
                msg = self._bus.recv(timeout=min(left, 0.05))
            except can.CanError as e:
                self.close()
                raise DeviceError(f"CAN {self.channel}: {e}") from e
            if msg is not None and self.codec.decode(msg.arbitration_id, bytes(msg.data)):
                self._first = msg
                break
        self._last_valid = self.timeout_clock()

    def read(self, sink: Sink) -> None:
        if self._bus is None:
            raise DeviceError(f"CAN {self.channel} is not open")
        if self._first is not None:
            first, self._first = self._first, None
            self._on_frame(first, sink)
        deadline = time.monotonic() + self.recv_timeout_s
        while True:
            left = deadline - time.monotonic()
            try:
                msg = self._bus.recv(timeout=max(0.0, left))
            except can.CanError as e:
                raise DeviceError(f"CAN {self.channel}: {e}") from e
            if msg is None:
                break
            self._on_frame(msg, sink)
            if left <= 0:
                break
        now = self.timeout_clock()
        if now - self._last_valid > self.data_timeout_s:
            self.health.timeouts += 1
            raise DeviceError(f"no MTi frames on CAN {self.interface}:{self.channel} for "
                              f"{now - self._last_valid:.1f} s")

    def _on_frame(self, msg: can.Message, sink: Sink) -> None:
        if msg.is_error_frame or msg.is_remote_frame:
            return
        decoded = self.codec.decode(msg.arbitration_id, bytes(msg.data))
        if decoded is None:
            if msg.arbitration_id in self.codec.ids:
                self.health.bad_frames += 1
            return
        kind, vals = decoded
        self._last_valid = self.timeout_clock()
        if kind == "error":
            self.health.extra["device_errors"] += 1
            self.health.last_error = f"MTi CAN error 0x{int(vals[0]):02X}"
            log.warning("%s: %s", self.name, self.health.last_error)
            return
        if kind not in self.messages:
            return
        if kind in self._group:  # a new group started before the last one completed
            self.health.extra["incomplete_groups"] += 1
            self._flush(sink)
        if not self._group:
            self._group_t = self.clock()
        self._group[kind] = vals
        if len(self._group) == len(self.messages):
            self._flush(sink)

    def _flush(self, sink: Sink) -> None:
        g, self._group = self._group, {}
        values: dict[str, float] = {}
        for kind, vals in g.items():
            if kind == "quaternion":
                vals = quat_to_euler_deg(vals)  # type: ignore[arg-type]
            for q, v in zip(_QUANTITIES[kind], vals, strict=True):
                values[q] = v
        if "packet_counter" in values:
            self._count_gap(int(values["packet_counter"]))
        st = values.get("sample_time_fine")
        t_dev = st * self.codec.layout.sample_time_scale_s if st is not None else None
        self.emit(sink, Reading(device=self.name, t_host=self._group_t, values=values,
                                invalid=frozenset(self._expected.difference(values)),
                                t_device=t_dev))

    def _count_gap(self, counter: int) -> None:
        prev = self._prev_counter
        self._prev_counter = counter
        if prev is not None:
            gap = (counter - prev - 1) & 0xFFFF
            if 0 < gap < 0x8000:
                self.health.extra["dropped_packets"] += gap

    def close(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            try:
                bus.shutdown()
            except (OSError, can.CanError):
                pass
