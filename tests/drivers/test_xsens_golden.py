"""Golden test: decode real MTi-G-710 captures and reproduce their published decoding.

The captures and their ``.golden`` text come from einride/xsens-go (MIT, see
tests/fixtures/xsens-mti-g710/README.md). A decoder that reproduces every printed
digit from the raw bytes is reading the real protocol, not our own idea of it.

The golden was printed by Go, so :func:`go_float` re-implements Go's ``%v`` for a
float64: the shortest round-trip digits (the same digits as Python's ``repr``), in
exponent form when the decimal exponent is < -4 or >= 6 (Go's %g rule for shortest
precision), otherwise plain, with no trailing ``.0``. Float32 items are printed
widened to float64 - the golden shows ``-0.017374228686094284``, not the shortest
float32 form ``-0.017374229`` - which is exactly what ``struct.unpack('>f')`` gives.
"""

from __future__ import annotations

import math
import struct
from decimal import Decimal
from pathlib import Path

import pytest

from drivers.xsens.mtdata2 import (
    ENU,
    FLOAT32,
    FLOAT64,
    FP1220,
    FP1632,
    ITEM_TYPES,
    NED,
    NWU,
    TYPE_MASK,
    DataItem,
    UtcTime,
    decode_mtdata2,
    decode_output_configuration,
)
from drivers.xsens.orientation import quat_to_euler_deg
from drivers.xsens.serial_driver import AGREEMENT_DEG, orientations_agree
from drivers.xsens.xbus import MID, XbusParser

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "xsens-mti-g710"
PREC = {FLOAT32: "Float32", FP1220: "FP1220", FP1632: "FP1632", FLOAT64: "Float64"}
FRAME = {ENU: "EastNorthUp", NED: "NorthEastDown", NWU: "NorthWestUp"}
GOLDEN_NAMES = {"UtcTime": "UTCTime", "GnssPvtData": "GNSSPVTData", "GnssSatInfo": "GNSSSatInfo",
                "PositionEcef": "PositionECEF"}
PVT_LABELS = ("ITOW", "Year", "Month", "Day", "Hour", "Min", "Sec", "Valid", "TAcc", "Nano",
              "FixType", "Flags", "NumSV", "Reserved1", "Lon", "Lat", "Height", "HMSL", "HAcc",
              "VAcc", "VelN", "VelE", "VelD", "GSpeed", "HeadMot", "SAcc", "HeadAcc",
              "HeadVeh", "GDOP", "PDOP", "TDOP", "VDOP", "HDOP", "NDOP", "EDOP")
LABELS = {"Quaternion": ("Q0", "Q1", "Q2", "Q3"), "DeltaQ": ("Q0", "Q1", "Q2", "Q3"),
          "LatLon": ("Lat", "Lon"), "RotationMatrix": tuple("ABCDEFGHI")}


def go_float(v: float) -> str:
    """Go's ``fmt`` ``%v`` of a float64."""
    if math.isnan(v):
        return "NaN"
    if math.isinf(v):
        return "+Inf" if v > 0 else "-Inf"
    s = "-" if math.copysign(1.0, v) < 0 else ""
    if v == 0.0:
        return s + "0"
    _, digits, exp = Decimal(repr(abs(v))).as_tuple()
    raw = "".join(map(str, digits))
    dp = len(raw) + int(exp)  # value = 0.<raw> * 10**dp; repr has no leading zero digits
    ds = raw.rstrip("0")
    x = dp - 1
    if x < -4 or x >= 6:
        mant = ds[0] + ("." + ds[1:] if len(ds) > 1 else "")
        return f"{s}{mant}e{'-' if x < 0 else '+'}{abs(x):02d}"
    if dp <= 0:
        return f"{s}0.{'0' * -dp}{ds}"
    if dp >= len(ds):
        return s + ds + "0" * (dp - len(ds))
    return f"{s}{ds[:dp]}.{ds[dp:]}"


@pytest.mark.parametrize("v,expected", [
    (1.0, "1"), (-0.017374228686094284, "-0.017374228686094284"), (1.5e-05, "1.5e-05"),
    (0.0001, "0.0001"), (123456.0, "123456"), (1234567.0, "1.234567e+06"), (0.0, "0"),
    (-2.5, "-2.5"), (100.0, "100"),
])
def test_go_float_matches_go_fmt(v: float, expected: str) -> None:
    assert go_float(v) == expected


def golden_header(item: DataItem) -> str:
    t = ITEM_TYPES[item.xdi & TYPE_MASK]
    name = GOLDEN_NAMES.get(t.name, t.name)
    if t.kind == "real":
        prec = PREC[item.xdi & 3]
        return f"{name}({FRAME[item.xdi & 0xC]},{prec})" if t.framed else f"{name}({prec})"
    return name


def golden_item(item: DataItem) -> list[str]:
    """Lines of one item as the golden prints them."""
    assert not item.name.endswith("?") and not item.name.startswith("Unknown"), item
    lines = [golden_header(item) + ":"]
    v = item.value
    if item.name in ("PacketCounter", "SampleTimeFine", "SampleTimeCoarse", "BaroPressure"):
        lines.append(f"  {v}")
    elif item.name == "StatusWord":
        lines.append(f"  {v:032b}")
    elif item.name == "StatusByte":
        lines.append(f"  {v:08b}")
    elif isinstance(v, UtcTime):
        frac = ("." + f"{v.nano:09d}".rstrip("0")) if v.nano else ""
        lines.append(f"  {v.year:04d}-{v.month:02d}-{v.day:02d}T{v.hour:02d}:{v.minute:02d}:"
                     f"{v.second:02d}{frac}Z")
    elif item.name == "GnssSatInfo":
        # the golden prints the header (iTOW, numSvs, three reserved bytes), not the
        # satellites that follow it
        itow, nsv, r1, r2, r3 = struct.unpack_from(">IBBBB", v)
        assert len(v) == 8 + 4 * nsv  # gnssId, svId, cno, flags per satellite
        lines += [f"  ITOW:{itow}", f"  NumSVS:{nsv}", f"  Res1:{r1}", f"  Res2:{r2}",
                  f"  Res3:{r3}"]
    elif isinstance(v, dict):
        lines += [f"  {label}:{x}" for label, x in zip(PVT_LABELS, v.values(), strict=True)]
    elif len(v) == 1:
        lines.append(f"  {go_float(v[0])}")
    else:
        labels = LABELS.get(item.name, ("X", "Y", "Z"))
        lines += [f"  {label}:{go_float(x)}" for label, x in zip(labels, v, strict=True)]
    return lines


def decode_capture(path: Path) -> tuple[list[str], XbusParser]:
    parser = XbusParser()
    blocks = []
    data = path.read_bytes()
    # Feed in awkward chunks to exercise the streaming path on real bytes.
    msgs = []
    for k in range(0, len(data), 37):
        msgs += parser.feed(data[k:k + 37])
    parser.finish()
    for m in msgs:
        assert m.mid == MID.MTDATA2
        lines: list[str] = []
        for item in decode_mtdata2(m.data):
            lines += golden_item(item)
        blocks.append("\n".join(lines) + "\n")
    return blocks, parser


@pytest.mark.parametrize("folder", ["1", "3", "5"])
def test_output_reproduces_golden(folder: str) -> None:
    blocks, parser = decode_capture(FIXTURES / folder / "output.bin")
    golden = (FIXTURES / folder / "output.golden").read_text()
    expected = [b + "\n" for b in golden.split("\n\n")[:-1]]
    assert len(blocks) == len(expected) == 100
    for k, (got, want) in enumerate(zip(blocks, expected, strict=True)):
        assert got == want, f"message {k} differs"
    assert "".join(b + "\n" for b in blocks) == golden
    assert parser.rejected_bytes == 0 and parser.bad_frames == 0


@pytest.mark.parametrize("folder", ["1", "3", "5"])
def test_outputconfig_reproduces_golden(folder: str) -> None:
    settings = decode_output_configuration((FIXTURES / folder / "outputconfig.bin").read_bytes())
    parts = []
    for s in settings:
        item = DataItem(s.xdi, ITEM_TYPES[s.xdi & TYPE_MASK].name, None, None, None)
        rate = "Max" if s.frequency == 0xFFFF else f"{s.frequency} Hz"
        parts.append(f"{golden_header(item)}:\n  {rate}")
    assert "\n".join(parts) == (FIXTURES / folder / "outputconfig.golden").read_text()


def test_a_real_mti_sends_one_orientation_in_every_form() -> None:
    """The driver drops a packet whose Euler angles and quaternion disagree by more than
    AGREEMENT_DEG, on the premise that the device derives both from one orientation in
    the same instant. Capture 5 holds a real MTi-G-710's rotation matrix and quaternion
    in the same packets: they agree to float32 rounding, far inside the tolerance, so
    the check drops no genuine packet."""
    blocks = 0
    worst = 0.0
    msgs = XbusParser().feed((FIXTURES / "5" / "output.bin").read_bytes())
    for m in msgs:
        items = {i.name: i.value for i in decode_mtdata2(m.data)}
        if "RotationMatrix" not in items or "Quaternion" not in items:
            continue
        blocks += 1
        # sent column by column (a, b, c = R11, R21, R31); Euler angles of R = Rz Ry Rx
        r11, r21, r31, _, _, r32, _, _, r33 = items["RotationMatrix"]
        e = (math.degrees(math.atan2(r32, r33)), -math.degrees(math.asin(r31)),
             math.degrees(math.atan2(r21, r11)))
        q = items["Quaternion"]
        assert orientations_agree(e, q), (m, e, q)
        assert orientations_agree(e, q, tol_deg=AGREEMENT_DEG / 100)
        worst = max(worst, max(abs(a - b) for a, b in zip(e, quat_to_euler_deg(q), strict=True)))
    assert blocks == 92
    assert worst < 1e-4, worst
