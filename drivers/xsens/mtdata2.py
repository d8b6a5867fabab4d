"""MTData2 (message 0x36) items: XDI identifiers, the four precisions, decode and encode.

An MTData2 payload is a sequence of packets ``XDI(2) SIZE(1) DATA(SIZE)``; unknown
identifiers are skipped by their size, never fatal (MTi user manual MT0605P section
5.3.3). An XDI is ``group | type | coordinate frame | precision``:

* bits 0-1 precision: 0 float32, 1 fixed point 12.20, 2 fixed point 16.32, 3 float64;
* bits 2-3 coordinate frame: 0 ENU, 4 NED, 8 NWU;
* ``xdi & 0xFFF0`` the data type (e.g. 0x2030 EulerAngles).

Identifier values are those of the vendor's SDK ``XsDataIdentifier`` enum
(xsdataidentifier.h). Fixed point formats (Xsens article "An explanation of the MTi
fixed point output formats"; SDK ``XsMessage_getDataFP1632``): fp12.20 is a signed
32-bit integer scaled by 2^-20; fp16.32 is six bytes, first the 32-bit fraction, then
the signed 16-bit integer part, value = (int16 * 2^32 + uint32 fraction) / 2^32.
GnssPvtData's 94-byte layout is the SDK's ``XsRawGnssPvtData``. Decoding all of this
reproduces the real MTi-G-710 captures in tests/fixtures/xsens-mti-g710 exactly.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any, NamedTuple

# --- precision and coordinate frame bits -------------------------------------------------

FLOAT32 = 0
FP1220 = 1
FP1632 = 2
FLOAT64 = 3
PRECISION_MASK = 0x0003
PRECISION_NAMES = {FLOAT32: "float32", FP1220: "fp1220", FP1632: "fp1632", FLOAT64: "float64"}
PRECISION_BY_NAME = {v: k for k, v in PRECISION_NAMES.items()}
PRECISION_SIZE = {FLOAT32: 4, FP1220: 4, FP1632: 6, FLOAT64: 8}

ENU = 0x0
NED = 0x4
NWU = 0x8
FRAME_MASK = 0x000C
FRAME_NAMES = {ENU: "ENU", NED: "NED", NWU: "NWU"}
FRAME_BY_NAME = {v: k for k, v in FRAME_NAMES.items()}

TYPE_MASK = 0xFFF0
MAX_FREQUENCY = 0xFFFF
"""Output frequency meaning 'every packet' (timestamps and status)."""


class XDI:
    """Data identifiers (type part; OR in precision and frame bits)."""

    TEMPERATURE = 0x0810
    UTC_TIME = 0x1010
    PACKET_COUNTER = 0x1020
    ITOW = 0x1030
    GNSS_AGE = 0x1040
    PRESSURE_AGE = 0x1050
    SAMPLE_TIME_FINE = 0x1060
    SAMPLE_TIME_COARSE = 0x1070
    FRAME_RANGE = 0x1080
    PACKET_COUNTER8 = 0x1090
    SAMPLE_TIME64 = 0x10A0
    QUATERNION = 0x2010
    ROTATION_MATRIX = 0x2020
    EULER_ANGLES = 0x2030
    BARO_PRESSURE = 0x3010
    DELTA_V = 0x4010
    ACCELERATION = 0x4020
    FREE_ACCELERATION = 0x4030
    ACCELERATION_HR = 0x4040
    ALTITUDE_MSL = 0x5010
    ALTITUDE_ELLIPSOID = 0x5020
    POSITION_ECEF = 0x5030
    LAT_LON = 0x5040
    GNSS_PVT_DATA = 0x7010
    GNSS_SAT_INFO = 0x7020
    RATE_OF_TURN = 0x8020
    DELTA_Q = 0x8030
    RATE_OF_TURN_HR = 0x8040
    MAGNETIC_FIELD = 0xC020
    MAGNETIC_FIELD_CORRECTED = 0xC030
    VELOCITY_XYZ = 0xD010
    STATUS_BYTE = 0xE010
    STATUS_WORD = 0xE020
    DEVICE_ID = 0xE080
    LOCATION_ID = 0xE090


# kind: "real" = floats in the item's precision (count = size / precision size);
# otherwise a struct format for integers, or a special decoder name.
@dataclass(frozen=True, slots=True)
class ItemType:
    """How one data type is laid out and named."""

    xdi: int
    name: str
    kind: str
    count: int = 0
    """For real items, the expected number of values (0 = any)."""
    framed: bool = False
    """Whether the coordinate-frame bits are meaningful (orientation, velocity)."""


ITEM_TYPES: dict[int, ItemType] = {t.xdi: t for t in (
    ItemType(XDI.TEMPERATURE, "Temperature", "real", 1),
    ItemType(XDI.UTC_TIME, "UtcTime", "utc"),
    ItemType(XDI.PACKET_COUNTER, "PacketCounter", ">H"),
    ItemType(XDI.ITOW, "Itow", ">I"),
    ItemType(XDI.GNSS_AGE, "GnssAge", ">B"),
    ItemType(XDI.PRESSURE_AGE, "PressureAge", ">B"),
    ItemType(XDI.SAMPLE_TIME_FINE, "SampleTimeFine", ">I"),
    ItemType(XDI.SAMPLE_TIME_COARSE, "SampleTimeCoarse", ">I"),
    ItemType(XDI.FRAME_RANGE, "FrameRange", ">HH"),
    ItemType(XDI.PACKET_COUNTER8, "PacketCounter8", ">B"),
    ItemType(XDI.SAMPLE_TIME64, "SampleTime64", ">Q"),
    ItemType(XDI.QUATERNION, "Quaternion", "real", 4, True),
    ItemType(XDI.ROTATION_MATRIX, "RotationMatrix", "real", 9, True),
    ItemType(XDI.EULER_ANGLES, "EulerAngles", "real", 3, True),
    ItemType(XDI.BARO_PRESSURE, "BaroPressure", ">I"),
    ItemType(XDI.DELTA_V, "DeltaV", "real", 3),
    ItemType(XDI.ACCELERATION, "Acceleration", "real", 3),
    ItemType(XDI.FREE_ACCELERATION, "FreeAcceleration", "real", 3),
    ItemType(XDI.ACCELERATION_HR, "AccelerationHR", "real", 3),
    ItemType(XDI.ALTITUDE_MSL, "AltitudeMsl", "real", 1),
    ItemType(XDI.ALTITUDE_ELLIPSOID, "AltitudeEllipsoid", "real", 1),
    ItemType(XDI.POSITION_ECEF, "PositionEcef", "real", 3),
    ItemType(XDI.LAT_LON, "LatLon", "real", 2),
    ItemType(XDI.GNSS_PVT_DATA, "GnssPvtData", "pvt"),
    ItemType(XDI.GNSS_SAT_INFO, "GnssSatInfo", "raw"),
    ItemType(XDI.RATE_OF_TURN, "RateOfTurn", "real", 3),
    ItemType(XDI.DELTA_Q, "DeltaQ", "real", 4),
    ItemType(XDI.RATE_OF_TURN_HR, "RateOfTurnHR", "real", 3),
    ItemType(XDI.MAGNETIC_FIELD, "MagneticField", "real", 3),
    ItemType(XDI.MAGNETIC_FIELD_CORRECTED, "MagneticFieldCorrected", "real", 3),
    ItemType(XDI.VELOCITY_XYZ, "VelocityXYZ", "real", 3, True),
    ItemType(XDI.STATUS_BYTE, "StatusByte", ">B"),
    ItemType(XDI.STATUS_WORD, "StatusWord", ">I"),
    ItemType(XDI.DEVICE_ID, "DeviceId", ">I"),
    ItemType(XDI.LOCATION_ID, "LocationId", ">H"),
)}
TYPE_BY_NAME: dict[str, ItemType] = {t.name: t for t in ITEM_TYPES.values()}


@dataclass(frozen=True, slots=True)
class UtcTime:
    """XDI_UtcTime: nanoseconds, date, time and validity flags."""

    nano: int
    year: int
    month: int
    day: int
    hour: int
    minute: int
    second: int
    flags: int


GNSS_PVT_FIELDS: tuple[str, ...] = (
    "itow", "year", "month", "day", "hour", "min", "sec", "valid", "t_acc", "nano",
    "fix_type", "flags", "num_sv", "reserved1", "lon", "lat", "height", "h_msl", "h_acc",
    "v_acc", "vel_n", "vel_e", "vel_d", "g_speed", "head_mot", "s_acc", "head_acc",
    "head_veh", "gdop", "pdop", "tdop", "vdop", "hdop", "ndop", "edop")
_PVT = struct.Struct(">IHBBBBBBIiBBBBiiiiIIiiiiiIIi7H")
_UTC = struct.Struct(">IHBBBBBB")
assert _PVT.size == 94 and len(GNSS_PVT_FIELDS) == 35  # layout self-check


class DataItem(NamedTuple):
    """One decoded MTData2 packet.

    ``value`` is a tuple of floats for real items, an int (or tuple of ints) for counters
    and status, :class:`UtcTime`, a dict for GnssPvtData, or ``bytes`` for unknown or
    malformed items (``name`` then starts with ``"Unknown"`` / ends with ``"?"``).
    """

    xdi: int
    name: str
    precision: int | None
    frame: int | None
    value: Any


# --- real-number codecs ------------------------------------------------------------------

_TWO20 = float(1 << 20)
_TWO32 = float(1 << 32)
_real_structs: dict[tuple[int, int], struct.Struct] = {}


def _real_struct(precision: int, n: int) -> struct.Struct:
    key = (precision, n)
    s = _real_structs.get(key)
    if s is None:
        code = {FLOAT32: "f", FP1220: "i", FP1632: "Ih", FLOAT64: "d"}[precision]
        s = _real_structs[key] = struct.Struct(">" + code * n)
    return s


def decode_reals(data: bytes | memoryview, precision: int, offset: int = 0,
                 n: int | None = None) -> tuple[float, ...]:
    """Decode ``n`` reals (default: as many as fit) of one precision; floats out."""
    size = PRECISION_SIZE[precision]
    if n is None:
        n = (len(data) - offset) // size
    raw = _real_struct(precision, n).unpack_from(data, offset)
    if precision == FLOAT32 or precision == FLOAT64:
        return raw
    if precision == FP1220:
        return tuple(v / _TWO20 for v in raw)
    return tuple((raw[k + 1] * 4294967296 + raw[k]) / _TWO32 for k in range(0, 2 * n, 2))


def fp1220_int(v: float) -> int:
    """Nearest fp12.20 integer, saturated to the int32 range."""
    q = round(v * (1 << 20))
    return max(-(1 << 31), min((1 << 31) - 1, q))


def fp1632_parts(v: float) -> tuple[int, int]:
    """(uint32 fraction, int16 integer part) of the nearest fp16.32 value, saturated."""
    q = round(v * (1 << 32))
    q = max(-(1 << 47), min((1 << 47) - 1, q))
    return q & 0xFFFFFFFF, q >> 32


def encode_reals(values: Iterable[float], precision: int) -> bytes:
    """Encode reals in one precision (fixed point rounds to nearest and saturates)."""
    vals = list(values)
    s = _real_struct(precision, len(vals))
    if precision == FLOAT32 or precision == FLOAT64:
        return s.pack(*vals)
    if precision == FP1220:
        return s.pack(*(fp1220_int(v) for v in vals))
    flat: list[int] = []
    for v in vals:
        flat.extend(fp1632_parts(v))
    return s.pack(*flat)


def quantize(v: float, precision: int) -> float:
    """The value a reader gets back after encoding ``v`` in ``precision``."""
    return decode_reals(encode_reals((v,), precision), precision)[0]


# --- item decode / encode ----------------------------------------------------------------

_int_structs: dict[str, struct.Struct] = {}


def iter_packets(payload: bytes | memoryview) -> Iterator[tuple[int, int, int]]:
    """Yield ``(xdi, offset, size)`` for each packet; stop at a truncated header/packet."""
    n = len(payload)
    off = 0
    while off + 3 <= n:
        xdi = (payload[off] << 8) | payload[off + 1]
        size = payload[off + 2]
        start = off + 3
        if start + size > n:
            return
        yield xdi, start, size
        off = start + size


def item_size(xdi: int) -> int | None:
    """Bytes of one item's data as the device sends it (None: unknown, or of any size)."""
    t = ITEM_TYPES.get(xdi & TYPE_MASK)
    if t is None:
        return None
    if t.kind == "real":
        return t.count * PRECISION_SIZE[xdi & PRECISION_MASK] if t.count else None
    if t.kind == "utc":
        return _UTC.size
    return struct.calcsize(t.kind) if t.kind.startswith(">") else None


def decode_item(xdi: int, data: bytes | memoryview, offset: int, size: int) -> DataItem:
    """Decode one packet; never raises for bad sizes or unknown ids (returns raw bytes)."""
    code, conv, name, prec, frame = _slot_plan(xdi, size)
    vals = struct.unpack_from(">" + code, data, offset)
    return DataItem(xdi, name, prec, frame, _convert(conv, vals, 0, len(vals)))


def _slot_plan(xdi: int, size: int) -> tuple[str, str, str, int | None, int | None]:
    """How to unpack one packet: (struct code, conversion, name, precision, frame)."""
    t = ITEM_TYPES.get(xdi & TYPE_MASK)
    if t is None:
        return f"{size}s", "bytes", f"Unknown0x{xdi:04X}", None, None
    kind = t.kind
    if kind == "real":
        prec = xdi & PRECISION_MASK
        frame = xdi & FRAME_MASK
        psize = PRECISION_SIZE[prec]
        n = size // psize
        if size % psize or (t.count and n != t.count) or n == 0:
            return f"{size}s", "bytes", t.name + "?", prec, frame
        code = {FLOAT32: "f", FP1220: "i", FP1632: "Ih", FLOAT64: "d"}[prec] * n
        return code, ("float", "fp1220", "fp1632", "float")[prec], t.name, prec, frame
    if kind == "utc":
        ok = size == _UTC.size
        return (_UTC.format[1:], "utc", t.name, None, None) if ok else (
            f"{size}s", "bytes", t.name + "?", None, None)
    if kind == "pvt":
        ok = size == _PVT.size
        return (_PVT.format[1:], "pvt", t.name, None, None) if ok else (
            f"{size}s", "bytes", t.name + "?", None, None)
    if kind == "raw":
        return f"{size}s", "bytes", t.name, None, None
    s = _int_structs.get(kind)
    if s is None:
        s = _int_structs[kind] = struct.Struct(kind)
    if size != s.size:
        return f"{size}s", "bytes", t.name + "?", None, None
    return kind[1:], ("int" if len(kind) == 2 else "ints"), t.name, None, None


def _convert(conv: str, vals: tuple[Any, ...], a: int, b: int) -> Any:
    if conv == "float":
        return vals[a:b]
    if conv == "int" or conv == "bytes":
        return vals[a]
    if conv == "fp1220":
        return tuple(v / _TWO20 for v in vals[a:b])
    if conv == "fp1632":
        return tuple((vals[k + 1] * 4294967296 + vals[k]) / _TWO32 for k in range(a, b, 2))
    if conv == "utc":
        return UtcTime(*vals[a:b])
    if conv == "pvt":
        return dict(zip(GNSS_PVT_FIELDS, vals[a:b], strict=True))
    return vals[a:b]  # "ints"


class _Layout:
    """A compiled MTData2 layout: one struct call checks all headers, one unpacks all data.

    Consecutive MTData2 messages of a configured device have the same packet sequence,
    so decoding is two C-level ``unpack_from`` calls plus a short loop per message.
    """

    __slots__ = ("heads", "expect", "data", "slots", "values_plan", "ids")

    def __init__(self, payload: bytes | memoryview) -> None:
        packets = list(iter_packets(payload))
        total = len(payload)
        head_fmt = [">"]
        data_fmt = [">"]
        expect: list[int] = []
        self.slots: list[tuple[int, str, str, int | None, int | None, int, int]] = []
        pos = 0
        nvals = 0
        for xdi, off, size in packets:
            code, conv, name, prec, frame = _slot_plan(xdi, size)
            head_fmt.append(f"HB{size}x")
            expect += [xdi, size]
            data_fmt.append(f"3x{code}")
            n = len(struct.unpack_from(">" + code, bytes(size)))
            self.slots.append((xdi, name, conv, prec, frame, nvals, nvals + n))
            nvals += n
            pos = off + size
        tail = total - pos
        if tail >= 3:  # a header whose size overruns the payload ended the walk: check it too
            head_fmt.append(f"HB{tail - 3}x")
            expect += [(payload[pos] << 8) | payload[pos + 1], payload[pos + 2]]
        elif tail:
            head_fmt.append(f"{tail}x")
        self.heads = struct.Struct("".join(head_fmt))
        self.expect = tuple(expect)
        self.data = struct.Struct("".join(data_fmt))
        self.values_plan = tuple((xdi & TYPE_MASK, _FAST_CONV.get(conv, _CONVERT), conv, a, b)
                                 for xdi, _n, conv, _p, _f, a, b in self.slots
                                 if conv != "bytes")
        """:func:`mtdata2_values`' steps: (key, how, conversion, first, end) per packet."""
        xdis = [xdi for xdi, *_ in self.slots]
        self.ids: frozenset[int] | None = (frozenset(xdis) if len(set(xdis)) == len(xdis)
                                           and not tail else None)
        """The packets' full identifiers (precision and frame bits too), or None if one
        repeats or bytes are left over: what :func:`mtdata2_values_ids` gives a driver to
        check its frames by."""


_SLICE, _ONE, _CONVERT = 0, 1, 2
_FAST_CONV = {"float": _SLICE, "int": _ONE}


_layouts: dict[int, list[_Layout]] = {}
_MAX_LAYOUTS = 512


def _layout(payload: bytes | memoryview) -> _Layout:
    n = len(payload)
    cands = _layouts.get(n)
    if cands:
        for lay in cands:
            if lay.heads.unpack_from(payload) == lay.expect:
                return lay
    lay = _Layout(payload)
    if sum(len(v) for v in _layouts.values()) >= _MAX_LAYOUTS:
        _layouts.clear()  # random input (fuzzing, noise) must not grow memory
    _layouts.setdefault(n, []).append(lay)
    return lay


def decode_mtdata2(payload: bytes | memoryview) -> list[DataItem]:
    """Decode every packet of an MTData2 payload, in order (a truncated tail is ignored)."""
    lay = _layout(payload)
    vals = lay.data.unpack_from(payload)
    return [DataItem(xdi, name, prec, frame, _convert(conv, vals, a, b))
            for xdi, name, conv, prec, frame, a, b in lay.slots]


def _values(lay: _Layout, payload: bytes | memoryview) -> dict[int, Any]:
    """``{xdi & 0xFFF0: value}`` of the payload's well-formed packets, by its layout."""
    vals = lay.data.unpack_from(payload)
    out: dict[int, Any] = {}
    for key, how, conv, a, b in lay.values_plan:  # planned once per layout
        if how == _SLICE:
            out[key] = vals[a:b]
        elif how == _ONE:
            out[key] = vals[a]
        else:
            out[key] = _convert(conv, vals, a, b)
    return out


def mtdata2_values(payload: bytes | memoryview) -> dict[int, Any]:
    """Fast path for drivers: ``{xdi & 0xFFF0: value}`` of the well-formed packets."""
    return _values(_layout(payload), payload)


def mtdata2_values_ids(payload: bytes | memoryview
                       ) -> tuple[dict[int, Any], frozenset[int] | None]:
    """:func:`mtdata2_values` and :func:`packet_ids`, from one layout look-up."""
    lay = _layout(payload)
    return _values(lay, payload), lay.ids


def packet_ids(payload: bytes | memoryview) -> frozenset[int] | None:
    """The payload's full packet identifiers (precision and frame bits too), or None if
    one repeats or bytes are left over: a device sends exactly the identifiers it was
    configured with, so a frame whose identifier bytes were hit shows here."""
    return _layout(payload).ids


def encode_item(xdi: int, value: Any) -> bytes:
    """Encode one packet (XDI, size, data) from a value shaped as :func:`decode_item` returns."""
    t = ITEM_TYPES.get(xdi & TYPE_MASK)
    if isinstance(value, (bytes, bytearray)):
        body = bytes(value)
    elif t is None:
        raise ValueError(f"cannot encode unknown XDI 0x{xdi:04X} from {type(value).__name__}")
    elif t.kind == "real":
        body = encode_reals(value, xdi & PRECISION_MASK)
    elif t.kind == "utc":
        u = value
        body = _UTC.pack(u.nano, u.year, u.month, u.day, u.hour, u.minute, u.second, u.flags)
    elif t.kind == "pvt":
        body = _PVT.pack(*(value[k] for k in GNSS_PVT_FIELDS))
    else:
        vals = value if isinstance(value, tuple) else (value,)
        body = struct.pack(t.kind, *vals)
    if len(body) > 255:
        raise ValueError(f"MTData2 packet too long: {len(body)} bytes")
    return struct.pack(">HB", xdi, len(body)) + body


def encode_mtdata2(items: Iterable[tuple[int, Any]]) -> bytes:
    """Encode an MTData2 payload from ``(xdi, value)`` pairs."""
    return b"".join(encode_item(x, v) for x, v in items)


# --- output configuration (SetOutputConfiguration 0xC0 / its ack 0xC1) --------------------

class OutputSetting(NamedTuple):
    """One entry of an output configuration: data identifier and output frequency in Hz."""

    xdi: int
    frequency: int


def encode_output_configuration(settings: Iterable[tuple[int, int]]) -> bytes:
    """Data of SetOutputConfiguration: N * (XDI u16, frequency u16); 0xFFFF = every packet."""
    return b"".join(struct.pack(">HH", x, f) for x, f in settings)


def decode_output_configuration(data: bytes) -> list[OutputSetting]:
    """Parse the data of an OutputConfiguration (0xC1) message."""
    n = len(data) // 4
    return [OutputSetting(*struct.unpack_from(">HH", data, 4 * k)) for k in range(n)]


def item_label(xdi: int) -> str:
    """Readable name of an XDI with its frame and precision, e.g. ``EulerAngles(NED,fp1632)``."""
    t = ITEM_TYPES.get(xdi & TYPE_MASK)
    if t is None:
        return f"Unknown0x{xdi:04X}"
    if t.kind != "real":
        return t.name
    prec = PRECISION_NAMES[xdi & PRECISION_MASK]
    if t.framed:
        return f"{t.name}({FRAME_NAMES.get(xdi & FRAME_MASK, '?')},{prec})"
    return f"{t.name}({prec})"
