"""MTData2 codec: every item by XDI, all four precisions, all three frames, fixed point bits.

Round trips cover each real-valued item type in float32, fp12.20, fp16.32 and float64
and in ENU, NED and NWU; the fixed-point tests pin the exact byte layout the protocol
defines (fp16.32: 4-byte fraction, then 2-byte signed integer part), which the real
fp16.32 capture in test_xsens_golden also confirms.
"""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.xsens.mtdata2 import (
    ENU,
    FLOAT32,
    FLOAT64,
    FP1220,
    FP1632,
    FRAME_MASK,
    ITEM_TYPES,
    NED,
    NWU,
    PRECISION_MASK,
    XDI,
    UtcTime,
    decode_item,
    decode_mtdata2,
    decode_output_configuration,
    decode_reals,
    encode_item,
    encode_mtdata2,
    encode_output_configuration,
    encode_reals,
    item_label,
    iter_packets,
    mtdata2_values,
    quantize,
)
from drivers.xsens.orientation import (
    euler_deg_to_matrix,
    euler_deg_to_quat,
    gravity_in_sensor,
    quat_to_euler_deg,
)

PRECISIONS = (FLOAT32, FP1220, FP1632, FLOAT64)
FRAMES = (ENU, NED, NWU)
REAL_TYPES = [t for t in ITEM_TYPES.values() if t.kind == "real"]
BRIEF_ITEMS = ("PacketCounter", "SampleTimeFine", "SampleTimeCoarse", "UtcTime", "Temperature",
               "Quaternion", "RotationMatrix", "EulerAngles", "Acceleration",
               "FreeAcceleration", "DeltaV", "RateOfTurn", "DeltaQ", "MagneticField",
               "StatusByte", "StatusWord", "LatLon", "AltitudeEllipsoid", "VelocityXYZ",
               "GnssPvtData")


def test_all_required_items_are_known() -> None:
    names = {t.name for t in ITEM_TYPES.values()}
    assert set(BRIEF_ITEMS) <= names
    assert ITEM_TYPES[XDI.EULER_ANGLES].name == "EulerAngles"
    assert (XDI.PACKET_COUNTER, XDI.SAMPLE_TIME_FINE, XDI.QUATERNION, XDI.STATUS_WORD) == (
        0x1020, 0x1060, 0x2010, 0xE020)


def tolerance(prec: int, v: float) -> float:
    return {FLOAT32: abs(v) * 2 ** -23 + 1e-45, FP1220: 2 ** -21, FP1632: 2 ** -33,
            FLOAT64: 0.0}[prec]


@pytest.mark.parametrize("prec", PRECISIONS)
@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("typ", REAL_TYPES, ids=lambda t: t.name)
def test_real_items_round_trip_every_precision_and_frame(typ: object, prec: int,
                                                          frame: int) -> None:
    n = typ.count  # type: ignore[attr-defined]
    xdi = typ.xdi | (frame if typ.framed else 0) | prec  # type: ignore[attr-defined]
    values = tuple((-1) ** k * (k + 0.123456789) * 3.7 for k in range(n))
    payload = encode_item(xdi, values)
    size = {FLOAT32: 4, FP1220: 4, FP1632: 6, FLOAT64: 8}[prec] * n
    assert payload[:3] == struct.pack(">HB", xdi, size)
    (item,) = decode_mtdata2(payload)
    assert item.xdi == xdi and item.name == typ.name  # type: ignore[attr-defined]
    assert item.precision == xdi & PRECISION_MASK and item.frame == xdi & FRAME_MASK
    for got, want in zip(item.value, values, strict=True):
        assert abs(got - want) <= tolerance(prec, want)
        assert got == quantize(want, prec)


@settings(max_examples=300, deadline=None)
@given(st.integers(-(2 ** 31), 2 ** 31 - 1))
def test_fp1220_is_int32_scaled_by_2_pow_minus_20(raw: int) -> None:
    v = raw / 2 ** 20
    b = encode_reals((v,), FP1220)
    assert b == struct.pack(">i", raw)
    assert decode_reals(b, FP1220) == (v,)


@settings(max_examples=300, deadline=None)
@given(st.integers(-(2 ** 47), 2 ** 47 - 1))
def test_fp1632_is_fraction_then_signed_integer_part(raw: int) -> None:
    v = raw / 2 ** 32
    b = encode_reals((v,), FP1632)
    assert b == struct.pack(">Ih", raw & 0xFFFFFFFF, raw >> 32)
    assert decode_reals(b, FP1632) == (v,)


def test_fixed_point_known_bit_patterns() -> None:
    assert encode_reals((1.0,), FP1632) == bytes.fromhex("000000000001")
    assert encode_reals((-1.5,), FP1632) == bytes.fromhex("80000000fffe")
    assert encode_reals((1.0 + 2 ** -32,), FP1632) == bytes.fromhex("000000010001")
    assert encode_reals((-1.0,), FP1220) == bytes.fromhex("fff00000")
    assert encode_reals((0.5,), FP1220) == bytes.fromhex("00080000")
    # Saturation instead of wrap-around outside the range.
    assert decode_reals(encode_reals((5000.0,), FP1220), FP1220)[0] == pytest.approx(2048, 1e-6)
    assert decode_reals(encode_reals((-1e6,), FP1632), FP1632)[0] == -32768.0


def test_integer_and_special_items_round_trip() -> None:
    utc = UtcTime(121900000, 2019, 1, 20, 13, 47, 24, 0x37)
    pvt = {k: i for i, k in enumerate(
        ("itow", "year", "month", "day", "hour", "min", "sec", "valid", "t_acc", "nano",
         "fix_type", "flags", "num_sv", "reserved1", "lon", "lat", "height", "h_msl", "h_acc",
         "v_acc", "vel_n", "vel_e", "vel_d", "g_speed", "head_mot", "s_acc", "head_acc",
         "head_veh", "gdop", "pdop", "tdop", "vdop", "hdop", "ndop", "edop"))}
    pvt["lon"] = -1187000000
    items = [(XDI.PACKET_COUNTER, 65535), (XDI.SAMPLE_TIME_FINE, 4294967295),
             (XDI.SAMPLE_TIME_COARSE, 123), (XDI.UTC_TIME, utc), (XDI.STATUS_BYTE, 0x81),
             (XDI.STATUS_WORD, 0x80000001), (XDI.GNSS_PVT_DATA, pvt),
             (XDI.GNSS_SAT_INFO, b"\x01\x02\x03")]
    decoded = decode_mtdata2(encode_mtdata2(items))
    assert [(d.xdi, d.value) for d in decoded] == items


def test_unknown_and_malformed_items_are_skipped_by_length() -> None:
    good = encode_item(XDI.PACKET_COUNTER, 7)
    unknown = struct.pack(">HB", 0x9990, 5) + b"12345"
    wrong_size = struct.pack(">HB", XDI.EULER_ANGLES, 5) + b"abcde"
    truncated = struct.pack(">HB", XDI.STATUS_WORD, 4) + b"\x00"
    items = decode_mtdata2(unknown + wrong_size + good + truncated)
    assert [i.name for i in items] == ["Unknown0x9990", "EulerAngles?", "PacketCounter"]
    assert items[0].value == b"12345" and items[2].value == 7
    assert decode_item(XDI.STATUS_WORD, b"\x00\x01", 0, 2).name == "StatusWord?"


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_decoding_random_payloads_never_raises(payload: bytes) -> None:
    decode_mtdata2(payload)


def test_output_configuration_codec_and_labels() -> None:
    cfg = [(XDI.PACKET_COUNTER, 0xFFFF), (XDI.EULER_ANGLES | NED | FP1632, 100)]
    data = encode_output_configuration(cfg)
    assert data == bytes.fromhex("1020ffff20360064")
    assert [tuple(s) for s in decode_output_configuration(data)] == cfg
    assert item_label(XDI.EULER_ANGLES | NED | FP1632) == "EulerAngles(NED,fp1632)"
    assert item_label(XDI.ACCELERATION | FLOAT64) == "Acceleration(float64)"
    assert item_label(XDI.STATUS_WORD) == "StatusWord"


@settings(max_examples=300, deadline=None)
@given(st.floats(-179.0, 179.0), st.floats(-89.0, 89.0), st.floats(-179.9, 179.9))
def test_quaternion_euler_round_trip(r: float, p: float, y: float) -> None:
    back = quat_to_euler_deg(euler_deg_to_quat(r, p, y))
    for a, b in zip(back, (r, p, y), strict=True):
        assert math.isclose(((a - b + 180) % 360) - 180, 0.0, abs_tol=1e-6)


def test_matrix_and_gravity_agree_with_quaternion() -> None:
    r, p, y = 10.0, -20.0, 30.0
    m = euler_deg_to_matrix(r, p, y)
    q0, q1, q2, q3 = euler_deg_to_quat(r, p, y)
    assert math.isclose(m[0][0], 2 * (q0 * q0 + q1 * q1) - 1, abs_tol=1e-12)
    assert math.isclose(m[2][1], 2 * (q2 * q3 + q0 * q1), abs_tol=1e-12)
    g = gravity_in_sensor(r, p)
    assert all(math.isclose(a, 9.81 * b, abs_tol=1e-12)
               for a, b in zip(g, (m[2][0], m[2][1], m[2][2]), strict=True))


xdi_st = st.one_of(st.sampled_from(sorted(ITEM_TYPES)), st.integers(0, 0xFFFF)).flatmap(
    lambda t: st.integers(0, 15).map(lambda low: (t & 0xFFF0) | low))
packet_st = st.tuples(xdi_st, st.binary(max_size=40)).map(
    lambda xb: struct.pack(">HB", xb[0], len(xb[1])) + xb[1])


@settings(max_examples=300, deadline=None)
@given(st.lists(packet_st, max_size=8), st.binary(max_size=4))
def test_compiled_layouts_match_item_by_item_decoding(packets: list[bytes], tail: bytes
                                                      ) -> None:
    payload = b"".join(packets) + tail
    ref = [decode_item(x, payload, o, s) for x, o, s in iter_packets(payload)]
    for _ in range(2):  # second time through the layout cache
        assert repr(decode_mtdata2(payload)) == repr(ref)
    expected = {i.xdi & 0xFFF0: i.value for i in ref if not isinstance(i.value, bytes)}
    assert repr(mtdata2_values(payload)) == repr(expected)
