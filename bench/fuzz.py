"""Fuzz the parsers with random and mutated inputs made from the committed captures.

Per parser it counts:

* crashes: an exception that is not the parser's documented error;
* hangs: one input taking longer than ``--hang-s``;
* corruptions accepted: for the MTi (Xbus), a frame corrupted in 1-4 bytes whose
  reading reaches the loop with values that differ from the clean frame's. The Xbus
  checksum is one byte, so about 1 in 256 such frames pass it: the driver stops them
  with what the frame already carries (the configured items with their exact
  identifiers, Euler angles that agree with the packet's quaternion, the packet counter
  and sample time advancing together, values finite, in range and not next to zero, the
  status word's undefined bits clear and its self-test bit steady, angles that cannot
  jump). ``xbus`` is the MTi sending both orientations (the default), ``xbus-euler``
  Euler angles alone (as before 2026-11-26). What still gets through is a change in an
  angle's low bits, or, with ``--extra-outputs``, in the rate of turn, the acceleration
  or the status word (which the loop does not use); the bench also counts those that
  move an angle by more than 0.01 deg, and ``--breakdown`` prints which field and which
  bits each accepted reading differs in, and how many differ only within the sensor's
  noise. The AR4000's ASCII protocol has no checksum at all, so a mutated digit is a
  valid distance: the driver stops what the handle cannot do (a distance further from
  the last one used than the crowd moves in the time between them); the bench counts
  what still reaches the loop and how far off it is.

    .venv/bin/python bench/fuzz.py [--parser all|xbus|xbus-euler|mti-can|ar4000|modbus|table|
                                             capture]
                                   [--n 1000000] [--seed 1] [--breakdown]
                                   [--extra-outputs ...] [--laser-max-speed M]

Goal (issue 12): 0 crashes, 0 hangs, 0 corrupted MTi frames accepted.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import random
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CAPTURE = ROOT / "hil_fixtures" / "captures" / "daemon-e2e"


def rx_bytes(name: str) -> bytes:
    from drivers.capture.format import read_serial_chunks

    return b"".join(c.data for c in read_serial_chunks(CAPTURE / name) if c.direction == "rx")


def mutate(rng: random.Random, data: bytes, max_edits: int = 4) -> bytes:
    """Bit flips, byte changes, inserts, deletes, a cut or a splice."""
    b = bytearray(data)
    for _ in range(rng.randint(1, max_edits)):
        op = rng.random()
        k = rng.randrange(len(b)) if b else 0
        if op < 0.35 and b:
            b[k] ^= 1 << rng.randrange(8)
        elif op < 0.6 and b:
            b[k] = rng.randrange(256)
        elif op < 0.75:
            b[k:k] = rng.randbytes(rng.randint(1, 8))
        elif op < 0.9 and b:
            del b[k:k + rng.randint(1, 8)]
        else:
            b = b[:k] if rng.random() < 0.5 else b + b[k:k + rng.randint(1, 40)]
    return bytes(b)


class Tally:
    def __init__(self, name: str, hang_s: float) -> None:
        self.name, self.hang_s = name, hang_s
        self.n = self.crashes = self.hangs = self.accepted = self.checked = self.severe = 0
        self.first_crash = ""

    def run(self, fn: Callable[[], Any], expected: tuple[type[BaseException], ...]) -> Any:
        t0 = time.perf_counter()
        out = None
        try:
            out = fn()
        except expected:
            pass
        except Exception as e:  # noqa: BLE001 - that is what is counted
            self.crashes += 1
            if not self.first_crash:
                self.first_crash = f"{type(e).__name__}: {e}"[:200]
        if time.perf_counter() - t0 > self.hang_s:
            self.hangs += 1
        self.n += 1
        return out


ANGLES = ("roll_deg", "pitch_deg", "yaw_deg")


def fuzz_xbus(n: int, rng: random.Random, t: Tally, orientation: str = "euler+quaternion",
              breakdown: list[list[tuple[str, float, float]]] | None = None,
              extra_outputs: tuple[str, ...] = ()) -> None:
    """Corrupt one MTData2 frame between two clean ones; parse and decode as the driver
    configured for ``orientation`` and ``extra_outputs``. The committed capture's MTi sent
    Euler angles, rate of turn, acceleration and status word; each of its packets is
    re-encoded with the configured items alone, in the configured order, and the
    quaternion of its own Euler angles where both orientations are asked for, as the
    emulator and a real device send them. ``breakdown`` collects, per accepted reading,
    (key, clean value, value read) of each value that differs."""
    from drivers.base import Reading
    from drivers.xsens.mtdata2 import TYPE_MASK, XDI, encode_item, mtdata2_values
    from drivers.xsens.orientation import euler_deg_to_quat
    from drivers.xsens.serial_driver import MtiSerialDriver
    from drivers.xsens.xbus import XbusMessage, XbusParser, encode_frame

    drv = MtiSerialDriver.from_config({"port": "/dev/null", "orientation": orientation,
                                       "extra_outputs": list(extra_outputs)})
    p = XbusParser()
    msgs = []
    for m in p.feed(rx_bytes("mti.serial.jsonl")):
        if m.mid != 0x36:
            continue
        v = mtdata2_values(m.data)
        v[XDI.QUATERNION] = euler_deg_to_quat(*v[XDI.EULER_ANGLES])
        msgs.append(XbusMessage(m.mid, b"".join(
            encode_item(xdi, v[xdi & TYPE_MASK]) for xdi, _ in drv.requested_outputs())))
    frames = [encode_frame(m.mid, m.data) for m in msgs]
    clean: list[dict[str, float]] = []
    for m in msgs:
        r = drv.decode(m.data)
        clean.append(dict(r.values) if r is not None else {})
    got: list[Reading] = []
    for _ in range(n):
        k = rng.randrange(1, len(frames) - 1)
        f = bytearray(frames[k])
        for _ in range(rng.randint(1, 4)):  # corruption inside the frame, length kept
            j = rng.randrange(1, len(f))
            f[j] = rng.randrange(256)
        bad = bytes(f)
        if bad == frames[k]:
            continue

        def one(bad: bytes = bad, k: int = k) -> None:
            parser = XbusParser()
            drv._prev_counter = None
            drv._prev_frame = None
            got.clear()
            msgs = parser.feed(frames[k - 1] + bad + frames[k + 1])
            if any(encode_frame(m.mid, m.data) not in frames for m in msgs):
                t.checked += 1  # the corrupted frame passed the checksum
            for m in msgs:
                if m.mid == 0x36:
                    r = drv.decode(m.data)
                    if r is not None:
                        drv.emit(got.append, r)
            # Every reading that reaches the loop must be one of the clean frames' (in
            # the quantities it gives as valid); anything else is a corruption let in.
            for r in got:
                if not any(all(key in c and abs(v - c[key]) <= 1e-9 * max(1.0, abs(c[key]))
                               for key, v in r.values.items())
                           for c in (clean[k - 1], clean[k], clean[k + 1])):
                    t.accepted += 1
                    if breakdown is not None:
                        breakdown.append([(key, clean[k][key], v)
                                          for key, v in r.values.items()
                                          if not (key in clean[k] and v == clean[k][key])])
                    # what the loop turns into joint angles, off by more than the sensor
                    # resolves (0.01 deg)
                    if any(abs(r.values[a] - c[a]) > 0.01 for a in ANGLES if a in r.values
                           for c in (clean[k],)):
                        t.severe += 1
        t.run(one, ())


def float32_bits(old: float, new: float) -> str:
    """Which part of a float32 a change hit: its highest differing bit, named."""
    import struct

    x = struct.unpack(">I", struct.pack(">f", old))[0] ^ struct.unpack(
        ">I", struct.pack(">f", new))[0]
    top = x.bit_length() - 1
    if top == 31:
        return "sign"
    if top >= 23:
        return "exponent"
    return f"mantissa bit {top}" if top >= 16 else "mantissa bits 0-15"


NOISE = {"gyr": 0.0013, "acc": 0.0068, "deg": 0.005}
"""What a change must exceed to be told from the sensor's own noise: one standard
deviation of a real MTi-G-710 at rest, sample to sample at 100 Hz (fixtures
``xsens-mti-g710/1`` and ``/3``: rate of turn 0.0013-0.0020 rad/s, acceleration
0.0068-0.0085 m/s^2, the smallest of each); for an angle the 0.005 deg its Euler angles
and quaternion may disagree by (its angles move 0.003-0.03 deg rms sample to sample)."""


def _noise(key: str) -> float:
    return NOISE[key[:3]] if key[:3] in NOISE else NOISE["deg"] if key.endswith("_deg") else 0.0


def print_breakdown(readings: list[list[tuple[str, float, float]]], accepted: int) -> None:
    """What the accepted readings differ in: per field, by the part of the float32 hit,
    with the largest absolute and relative change and how many changes stay within the
    sensor's noise (:data:`NOISE`); then the readings whose every change does."""
    from collections import defaultdict

    groups: dict[tuple[str, str], list[tuple[float, float]]] = defaultdict(list)
    rows = [row for r in readings for row in r]
    for key, old, new in rows:
        if key in ("packet_counter", "sample_time_fine", "status_word"):
            x = int(old) ^ int(new)
            part = "bits " + ",".join(f"{8 * h}-{8 * h + 7}" for h in sorted(
                {b // 8 for b in range(32) if x >> b & 1}))
        else:
            part = float32_bits(old, new) if math.isfinite(new) else "non-finite"
        groups[(key, part)].append((old, new))
    print(f"  breakdown of the {accepted} accepted ({len(rows)} values differ):")
    print(f"    {'field':<17s} {'part hit':<20s} {'n':>5s} {'max |change|':>13s} "
          f"{'max rel':>9s} {'in noise':>8s}")
    for (key, part), vals in sorted(groups.items(), key=lambda kv: (kv[0][0], -len(kv[1]))):
        d = max(abs(b - a) for a, b in vals)
        rel = max(abs(b - a) / abs(a) if a else math.inf for a, b in vals)
        quiet = sum(abs(b - a) <= _noise(key) for a, b in vals)
        print(f"    {key:<17s} {part:<20s} {len(vals):5d} {d:13.4g} {rel:9.2g} {quiet:8d}")
    quiet_r = [r for r in readings if all(abs(b - a) <= _noise(k) for k, a, b in r)]
    big: dict[str, float] = defaultdict(float)
    for r in quiet_r:
        for k, a, b in r:
            big[k] = max(big[k], abs(b - a))
    print(f"  of the {len(readings)}, every change within the sensor's noise: {len(quiet_r)} "
          "(largest: " + ", ".join(f"{k} {v:.2g}" for k, v in sorted(big.items())) + ")")
    fields: dict[str, int] = defaultdict(int)
    for r in readings:
        if r not in quiet_r:
            loud = sorted({k for k, a, b in r if abs(b - a) > _noise(k)})
            fields[" + ".join(loud)] += 1
    print("  beyond the noise, by field: " + ", ".join(
        f"{k} {n}" for k, n in sorted(fields.items(), key=lambda kv: -kv[1])))


def fuzz_ar4000(n: int, rng: random.Random, t: Tally,
                errors: list[float] | None = None, max_speed_mps: float | None = None) -> None:
    """Corrupt one line of the committed capture's laser stream between clean ones (two
    before it, so that the driver has a distance in use, as it streams; one after) and
    read them through the driver (its line splitter, parser and rules), the lines 20 ms
    apart as the laser sent them. ``t.checked`` counts corrupted lines that
    still parse, to another value than the clean one's (what the protocol alone lets
    through: it has no checksum); ``t.accepted`` the readings that reach the loop with a
    distance none of the three clean lines had; ``errors`` collects, per such reading,
    how far it is from the clean line's distance (metres). ``max_speed_mps`` sets the
    driver's key of that name (a huge value switches its jump rule off)."""
    from drivers.acuity.ar4000 import DISTANCE, Ar4000Config, Ar4000Driver, LineSplitter, parse_line
    from drivers.base import Reading

    cfg = Ar4000Config.from_config({"port": "/dev/null", "sample_interval_us": 20000} | (
        {} if max_speed_mps is None else {"max_speed_mps": max_speed_mps}))
    drv = Ar4000Driver("laser", cfg)
    lines = [x + b"\n" for x in rx_bytes("laser.serial.jsonl").split(b"\n")[1:-1]]
    parsed = [parse_line(x.rstrip(b"\r\n"), cfg.unit_m) for x in lines]
    value = [v for v in parsed if v is not None]
    assert len(value) == len(parsed), "every clean line of the committed capture parses"
    got: list[Reading] = []
    dt = cfg.interval_s
    for _ in range(n):
        k = rng.randrange(2, len(lines) - 1)
        bad = mutate(rng, lines[k])
        if bad == lines[k]:
            continue

        def one(bad: bytes = bad, k: int = k) -> None:
            drv._splitter.clear()
            drv._prev = drv._used = None
            drv._parse(lines[k - 2], got.append, -dt)
            got.clear()
            drv._parse(lines[k - 1], got.append, 0.0)
            drv._parse(bad, got.append, dt)
            drv._parse(lines[k + 1], got.append, 2 * dt)
            split = LineSplitter(cfg.max_line_bytes)
            if any(v is not None and v != value[k] for v in (
                    parse_line(x, cfg.unit_m) for x in split.feed(bad + b"\n"))):
                t.checked += 1
            near = (value[k - 1], value[k], value[k + 1])
            for r in got:
                v = r.values.get(DISTANCE)
                if v is not None and v not in near:
                    t.accepted += 1
                    if errors is not None:
                        errors.append(abs(v - value[k]))
        t.run(one, ())


def fuzz_mti_can(n: int, rng: random.Random, t: Tally) -> None:
    """CAN frames through the MTi CAN driver (``_on_frame``, group assembly, ``emit``):
    half the committed CAN capture's frames with their data mutated (bytes flipped,
    changed, gained, lost; at most 8), sometimes their id or flags, half random frames
    (an MTi id or any 11-bit id, 0-8 random bytes), each between clean frames. A
    crash is any exception, or a reading with a value that is not finite.
    ``t.checked`` counts fuzzed frames the driver decodes, ``t.accepted`` those of them
    that put other values than the frame they replace into a reading. On a real bus the
    controller's CRC-15 drops a corrupted frame before software sees it (every burst
    of up to 15 bits, and all but 2^-15 of the rest), so those are what a corruption
    past the CRC would do; the driver only listens."""
    import can

    from drivers.base import Reading
    from drivers.capture.format import read_can_messages
    from drivers.xsens.can_driver import MtiCanDriver

    cap = ROOT / "hil_fixtures" / "captures" / "can-rtu-empty-full"
    start = json.loads((cap / "manifest.json").read_text())["start_unix"]
    clean = [m for _, m in read_can_messages(cap / "mti.can.log", start)]
    drv = MtiCanDriver.from_config({"name": "mti"})
    ids = drv.codec.ids
    got: list[Reading] = []
    for _ in range(n):
        k = rng.randrange(1, len(clean) - 1)
        if rng.random() < 0.5:
            m = clean[k]
            data = mutate(rng, bytes(m.data))[:8]
            aid = m.arbitration_id ^ (1 << rng.randrange(11)) if rng.random() < 0.2 \
                else m.arbitration_id
        else:
            data = rng.randbytes(rng.randint(0, 8))
            aid = rng.choice(ids) if rng.random() < 0.7 else rng.randrange(0x800)
        fuzzed = can.Message(arbitration_id=aid, data=data, is_extended_id=False,
                             is_error_frame=rng.random() < 0.02,
                             is_remote_frame=rng.random() < 0.02)

        def one(fuzzed: can.Message = fuzzed, k: int = k) -> None:
            drv._group.clear()
            drv._prev_counter = None
            got.clear()
            for m in (*clean[k - 6:k], fuzzed, *clean[k + 1:k + 7]):
                before = len(got)
                drv._on_frame(m, lambda r: drv.emit(got.append, r))
                if m is fuzzed and not (m.is_error_frame or m.is_remote_frame):
                    dec = drv.codec.decode(m.arbitration_id, bytes(m.data))
                    if dec is not None:
                        t.checked += 1
                        if dec[0] in drv.messages and dec != drv.codec.decode(
                                clean[k].arbitration_id, bytes(clean[k].data)):
                            t.accepted += 1
                for r in got[before:]:
                    if not all(math.isfinite(v) for v in r.values.values()):
                        raise AssertionError(f"non-finite value from {m}")
        t.run(one, ())


def fuzz_text(n: int, rng: random.Random, t: Tally, kind: str) -> None:
    """The signals table reader and the capture readers on mutated files."""
    from drivers.capture.format import CaptureFormatError, read_modbus_reads, read_serial_chunks
    from shoveld.signals.table import SignalsFormatError, read_table

    if kind == "table":
        from shoveld.signals.table import write_table
        from shoveld.sim.scenario import simulate_cycles

        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "t.csv"
            tab = simulate_cycles(1, seed=1).table
            write_table(path, tab.slice(tab.time < 2.0))
            base = path.read_bytes()
        for _ in range(n):
            data = mutate(rng, base, 6)

            def one(data: bytes = data) -> None:
                try:
                    text = data.decode("utf-8")
                except UnicodeDecodeError:
                    return
                read_table("fuzz.csv", text)
            t.run(one, (SignalsFormatError,))
        return
    with tempfile.TemporaryDirectory() as tmp:
        for name, reader in (("laser.serial.jsonl", read_serial_chunks),
                             ("adc_motors.modbus.jsonl", read_modbus_reads)):
            lines = (CAPTURE / name).read_bytes().splitlines(keepends=True)
            path = Path(tmp) / name
            for _ in range(n // 2):
                a = rng.randrange(1, max(2, len(lines) - 20))
                data = mutate(rng, b"".join(lines[:1] + lines[a:a + 12]), 5)
                path.write_bytes(data)

                def read_all(reader: Callable[[Path], Iterable[object]] = reader,
                             path: Path = path) -> None:
                    for _ in reader(path):
                        pass
                t.run(read_all, (CaptureFormatError,))


def fuzz_modbus(n: int, rng: random.Random, t: Tally) -> None:
    """Register words through the channel map's decoders (every 16-bit word, then random
    blocks), and the raw-to-value scaling: finite values or a saturation mark."""
    from hil_fixtures.virtual_shovel import MOTOR_CHANNELS

    chans = list(MOTOR_CHANNELS)
    decoders = [c.word_decoder() for c in chans]
    for _ in range(n):
        w = rng.randrange(65536)

        def one(w: int = w) -> None:
            for d in decoders:
                v = d(w)
                if not (math.isfinite(v) or math.isnan(v)):
                    raise AssertionError(f"word {w} decoded to {v}")
        t.run(one, ())


PARSERS = ("xbus", "xbus-euler", "mti-can", "ar4000", "modbus", "table", "capture")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--parser", default="all", choices=("all", *PARSERS))
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--hang-s", type=float, default=1.0)
    ap.add_argument("--breakdown", action="store_true",
                    help="MTi: what each accepted reading differs in (field, bits, size)")
    ap.add_argument("--extra-outputs", default="",
                    help="MTi: what it also sends, comma-separated (rate_of_turn,"
                         "acceleration,status_word); default none, as the driver's default")
    ap.add_argument("--laser-max-speed", type=float, default=None,
                    help="AR4000: the driver's max_speed_mps (default its default; 1e9 "
                         "switches the jump rule off)")
    args = ap.parse_args()
    logging.disable(logging.WARNING)  # (a torn last line is warned about, by design)
    names = PARSERS if args.parser == "all" else (args.parser,)
    print(f"{'parser':<9s} {'inputs':>9s} {'crashes':>8s} {'hangs':>6s} {'accepted':>9s} "
          f"{'of':>8s} {'s':>6s}  note")
    for name in names:
        rng = random.Random(args.seed)
        t = Tally(name, args.hang_s)
        t0 = time.perf_counter()
        if name.startswith("xbus"):
            rows: list[list[tuple[str, float, float]]] | None = [] if args.breakdown else None
            extras = tuple(x for x in args.extra_outputs.split(",") if x)
            fuzz_xbus(args.n, rng, t, "euler" if name == "xbus-euler" else "euler+quaternion",
                      rows, extras)
            note = ("readings from corrupted frames that reached the loop; 'of': corrupted "
                    "frames that passed the checksum; MTi sending "
                    + ("Euler angles alone" if name == "xbus-euler"
                       else "Euler angles and quaternion (the default)")
                    + (" and " + ", ".join(extras) if extras else ""))
        elif name == "ar4000":
            errors: list[float] = []
            fuzz_ar4000(args.n, rng, t, errors, args.laser_max_speed)
            note = ("readings from corrupted lines that reached the loop; 'of': corrupted "
                    "lines that parse to another value (the protocol has no checksum)")
        elif name == "mti-can":
            fuzz_mti_can(args.n, rng, t)
            note = ("MTi CAN frames, mutated and random, whose other values reach a reading; "
                    "'of': fuzzed frames decoded (a real bus's CRC-15 drops corrupted ones "
                    "before software)")
        elif name == "modbus":
            fuzz_modbus(args.n, rng, t)
            note = "register words through every channel decoder"
        else:
            fuzz_text(args.n, rng, t, name)
            note = ("signals tables" if name == "table" else "serial and Modbus captures") + \
                " (documented errors are not crashes)"
        dt = time.perf_counter() - t0
        print(f"{name:<9s} {t.n:9d} {t.crashes:8d} {t.hangs:6d} {t.accepted:9d} "
              f"{t.checked:8d} {dt:6.0f}  {note}", flush=True)
        if name == "ar4000" and errors:
            e = sorted(errors)
            print("  of the accepted, off the clean distance by more than 3 mm: "
                  f"{sum(x > 0.003 for x in e)}, 10 mm: {sum(x > 0.010 for x in e)}, "
                  f"30 mm: {sum(x > 0.030 for x in e)}; median {1e3 * e[len(e) // 2]:.0f} mm, "
                  f"largest {1e3 * e[-1]:.0f} mm")
        if name.startswith("xbus"):
            print(f"  of the accepted, with an angle off by more than 0.01 deg: {t.severe}")
            if rows is not None:
                print_breakdown(rows, t.accepted)
        if t.first_crash:
            print(f"  first crash: {t.first_crash}", file=sys.stderr)


if __name__ == "__main__":
    main()
