"""The capture format (``shoveld-capture/1``): a folder holding what devices said.

A capture is a directory with ``manifest.json`` and one recording per device::

    manifest.json           what was recorded, how, and the installation
    <name>.serial.jsonl     serial devices: raw byte chunks with host receive times
    <name>.can.log          CAN devices: candump log (python-can / can-utils read it)
    <name>.modbus.jsonl     Modbus devices: every register read and its outcome

All times are on one *capture clock*: seconds since the capture started (the
recorder's monotonic clock), so devices line up with each other. CAN logs carry
``start_unix + t`` so tools that expect epoch timestamps show wall time. The
formats are line-oriented text on purpose: a capture can be written by hand or by
another program from ``docs/captures.md`` alone, and a reader error names the file
and line. Every reader raises :class:`CaptureFormatError`.
"""

from __future__ import annotations

import datetime as _dt
import itertools
import json
import logging
import math
import operator
import os
import re
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, is_dataclass
from pathlib import Path
from typing import Any

FORMAT_NAME = "shoveld-capture"
FORMAT_VERSION = 1
SERIAL_FORMAT = "shoveld-serial-chunks"
MODBUS_FORMAT = "shoveld-modbus-reads"
SERIAL_KINDS = frozenset({"ar4000", "mti_serial"})
CAN_KINDS = frozenset({"mti_can"})
MODBUS_KINDS = frozenset({"modbus_tcp", "modbus_rtu"})
KINDS = SERIAL_KINDS | CAN_KINDS | MODBUS_KINDS
_FLUSH_EVERY_S = 1.0


class CaptureFormatError(ValueError):
    """A capture that does not follow the format; the message names file and line."""

    def __init__(self, path: str | os.PathLike[str], line: int | None, message: str) -> None:
        where = str(path) if line is None else f"{path}:{line}"
        super().__init__(f"{where}: {message}")
        self.path = str(path)
        self.line = line


# --------------------------------------------------------------------------- records


@dataclass(frozen=True, slots=True)
class SerialChunk:
    """Bytes that crossed a serial line in one read (``rx``) or write (``tx``)."""

    t: float
    direction: str
    data: bytes


SerialColumns = tuple[list[float], list[str], list[bytes]]
"""A serial recording as columns: each chunk's time, direction (``rx``/``tx``), bytes."""


@dataclass(frozen=True, slots=True)
class RegisterRead:
    """One Modbus register read and its outcome.

    Exactly one of ``registers`` (success: raw 16-bit words as read),
    ``error == "timeout"`` (no answer) or ``error == "exception"`` with
    ``exception_code`` (the module answered with a Modbus exception) holds.
    """

    t: float
    unit: int
    function: int
    address: int
    count: int
    registers: tuple[int, ...] | None = None
    error: str | None = None
    exception_code: int | None = None

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {"t": round(self.t, 6), "unit": self.unit, "fc": self.function,
                             "addr": self.address, "count": self.count}
        if self.registers is not None:
            d["regs"] = list(self.registers)
        else:
            d["error"] = self.error
            if self.exception_code is not None:
                d["code"] = self.exception_code
        return d


@dataclass
class DeviceEntry:
    """A device as the manifest lists it."""

    name: str
    kind: str
    file: str
    settings: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {"kind": self.kind, "file": self.file, **self.settings}


@dataclass
class Capture:
    """A capture folder opened for reading (manifest checked, files not yet read)."""

    path: Path
    manifest: dict[str, Any]
    devices: dict[str, DeviceEntry]

    @property
    def start_unix(self) -> float:
        return float(self.manifest.get("start_unix", 0.0))

    @property
    def installation(self) -> dict[str, Any]:
        return dict(self.manifest.get("installation") or {})

    def file(self, name: str) -> Path:
        return self.path / self.devices[name].file

    def serial_chunks(self, name: str) -> Iterator[SerialChunk]:
        return read_serial_chunks(self.file(name))

    def serial_columns(self, name: str) -> SerialColumns:
        return read_serial_columns(self.file(name))

    def modbus_reads(self, name: str) -> Iterator[RegisterRead]:
        return read_modbus_reads(self.file(name))

    def modbus_recording(self, name: str) -> RegisterColumns | list[RegisterRead]:
        return read_modbus_recording(self.file(name))

    def can_messages(self, name: str) -> Iterator[tuple[float, Any]]:
        return read_can_messages(self.file(name), self.start_unix)

    def duration_s(self) -> float:
        """Recorded length: the manifest's value, else the last timestamp found."""
        if isinstance(self.manifest.get("duration_s"), int | float):
            return float(self.manifest["duration_s"])
        last = 0.0
        for name, dev in self.devices.items():
            if dev.kind in SERIAL_KINDS:
                for c in self.serial_chunks(name):
                    last = max(last, c.t)
            elif dev.kind in MODBUS_KINDS:
                for r in self.modbus_reads(name):
                    last = max(last, r.t)
            else:
                for t, _ in self.can_messages(name):
                    last = max(last, t)
        return last


# --------------------------------------------------------------------------- reading


def _json_line(path: Path, lineno: int, text: str) -> dict[str, Any]:
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as e:
        raise CaptureFormatError(path, lineno, f"not valid JSON ({e.msg} at column {e.colno})"
                                 ) from None
    except RecursionError:
        raise CaptureFormatError(path, lineno, "not valid JSON (nested too deeply)") from None
    except ValueError as e:  # e.g. an integer of more than 4300 digits
        raise CaptureFormatError(path, lineno, f"not valid JSON ({e})") from None
    if not isinstance(obj, dict):
        raise CaptureFormatError(path, lineno, "expected a JSON object")
    return obj


log = logging.getLogger(__name__)


def _record(path: Path, lineno: int, text: str) -> dict[str, Any] | None:
    """One record; None for a torn last line. A recorder cut by a power failure leaves
    its last line without its newline and half written: the capture is replayed up to
    it, and the log says where it stopped. A bad line anywhere else is an error."""
    if text.endswith("\n"):
        return _json_line(path, lineno, text)
    try:
        return _json_line(path, lineno, text)
    except CaptureFormatError as e:
        log.warning("%s:%d: the last line is cut off (the recording was interrupted); replayed "
                    "up to line %d (%s)", path, lineno, lineno - 1, e)
        return None


def _lines(path: Path) -> Iterator[tuple[int, str]]:
    try:
        f = open(path, encoding="utf-8")
    except OSError as e:
        raise CaptureFormatError(path, None, f"cannot read: {e.strerror}") from None
    with f:
        try:
            for i, line in enumerate(f, start=1):
                if line.strip():
                    yield i, line
        except UnicodeDecodeError as e:
            raise CaptureFormatError(path, None, f"not UTF-8 text (byte offset {e.start})"
                                     ) from None


def _header(path: Path, it: Iterator[tuple[int, str]], expected: str) -> dict[str, Any]:
    try:
        lineno, text = next(it)
    except StopIteration:
        raise CaptureFormatError(path, None, f"empty file (expected a {expected!r} header line)"
                                 ) from None
    h = _json_line(path, lineno, text)
    if h.get("format") != expected:
        raise CaptureFormatError(path, lineno, f"header 'format' is {h.get('format')!r}; "
                                 f"expected {expected!r}")
    if h.get("version") != 1:
        raise CaptureFormatError(path, lineno, f"header 'version' is {h.get('version')!r}; "
                                 "this reader understands version 1")
    return h


def _time(path: Path, lineno: int, obj: dict[str, Any], prev: float) -> float:
    t = obj.get("t")
    if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
        raise CaptureFormatError(path, lineno, f"'t' must be a finite number of seconds, got {t!r}")
    if t < prev:
        raise CaptureFormatError(path, lineno,
                                 f"'t' {t} goes back in time (previous record {prev})")
    return float(t)


def _records(path: Path, expected: str) -> Iterator[tuple[int, dict[str, Any], float]]:
    """The line-by-line path's walk of a JSON-lines recording: each record after the
    ``expected`` header with its line number and its time (never before the last one's),
    up to a torn last line."""
    it = _lines(path)
    _header(path, it, expected)
    prev = -math.inf
    for lineno, text in it:
        obj = _record(path, lineno, text)
        if obj is None:
            return
        prev = _time(path, lineno, obj, prev)
        yield lineno, obj, prev


# The recorder's own line shapes, matched over a whole file at once: many times faster
# than a JSON parse per line. Only a file whose every record has one of these shapes
# and passes the same checks is read this way; anything else (another spelling, an
# error, a torn last line) goes through the line-by-line reader, which names the line.
_NUM = r"-?(?:0|[1-9][0-9]{0,15})(?:\.[0-9]{1,17})?(?:[eE][+-]?[0-9]{1,3})?"
_INT = r"(?:0|[1-9][0-9]{0,5})"
_SERIAL_LINE = re.compile(
    rf'^\{{"t":({_NUM}),"d":"(rx|tx)","hex":"([0-9a-fA-F]*)"\}}$', re.M)
_MODBUS_LINE = re.compile(
    rf'^\{{"t":({_NUM}),"unit":({_INT}),"fc":({_INT}),"addr":({_INT}),"count":({_INT}),'
    rf'(?:"regs":\[((?:{_INT},)*{_INT})\]|"error":"timeout"|"error":"exception",'
    rf'"code":({_INT}))\}}$', re.M)


def _bulk_records(path: Path, expected: str, line: re.Pattern[str]
                  ) -> list[tuple[str, ...]] | None:
    """Every record line of a file as ``line``'s groups, or None if the file needs the
    line-by-line reader (unreadable, another header, a record of another shape)."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    head, _, body = text.partition("\n")
    try:
        h = json.loads(head)
    except ValueError:
        return None
    if not isinstance(h, dict) or h.get("format") != expected or h.get("version") != 1:
        return None
    recs = line.findall(body)
    # One match per line at most (anchored): as many matches as lines = every line
    # matched (a blank line never matches, so a file with one goes line by line).
    lines = body.count("\n") + (not body.endswith("\n")) if body else 0
    if len(recs) != lines:
        return None
    return recs


def _times_ok(times: list[float]) -> bool:
    """Every time finite and none before the one above it (the readers' rule)."""
    return all(map(math.isfinite, times)) and all(
        map(operator.le, times, itertools.islice(times, 1, None)))


def _fast_serial_columns(path: Path) -> SerialColumns | None:
    recs = _bulk_records(path, SERIAL_FORMAT, _SERIAL_LINE)
    if recs is None:
        return None
    if not recs:
        return [], [], []
    ts, ds, hs = zip(*recs, strict=True)
    times = list(map(float, ts))
    if not _times_ok(times):
        return None
    try:
        data = list(map(bytes.fromhex, hs))
    except ValueError:  # an odd number of hex digits
        return None
    return times, list(ds), data


def _fast_serial_chunks(path: Path) -> list[SerialChunk] | None:
    cols = _fast_serial_columns(path)
    return None if cols is None else list(map(SerialChunk, *cols))


def read_serial_columns(path: str | os.PathLike[str]) -> SerialColumns:
    """The chunks of a ``*.serial.jsonl`` file as columns, in file (= time) order: what
    :func:`read_serial_chunks` yields, without a :class:`SerialChunk` per chunk (the
    fast replay keeps only the columns; the objects were a third of reading the file).
    The same errors as :func:`read_serial_chunks`."""
    p = Path(path)
    cols = _fast_serial_columns(p)
    if cols is not None:
        return cols
    chunks = list(read_serial_chunks(p, whole_file=False))
    return [c.t for c in chunks], [c.direction for c in chunks], [c.data for c in chunks]


def _head_ok(unit: int, fc: int, addr: int, count: int) -> bool:
    """A record's block as the whole-file path accepts it (anything else is left to the
    line-by-line reader, which names what is wrong)."""
    return unit <= 255 and 3 <= fc <= 4 and addr <= 65535 and 1 <= count <= 125


def _fast_modbus_reads(path: Path, recs: list[tuple[str, ...]] | None = None
                       ) -> list[RegisterRead] | None:
    """The whole-file path's records (``recs``: the file's line matches, if already
    made), or None where the line-by-line reader must read it."""
    if recs is None:
        recs = _bulk_records(path, MODBUS_FORMAT, _MODBUS_LINE)
    if recs is None:
        return None
    if recs and all(r[5] for r in recs):
        return _answered_reads(recs)
    out = []
    prev = -math.inf
    isfinite = math.isfinite
    for ts, us, fs, As, cs, regs_s, code_s in recs:
        t = float(ts)
        unit, fc, addr, count = int(us), int(fs), int(As), int(cs)
        if not (t >= prev and isfinite(t) and _head_ok(unit, fc, addr, count)):
            return None
        prev = t
        if regs_s:
            regs = tuple(map(int, regs_s.split(",")))
            if len(regs) != count or max(regs) > 65535:
                return None
            out.append(RegisterRead(t, unit, fc, addr, count, registers=regs))
        elif code_s:
            code = int(code_s)
            if not 1 <= code <= 255:
                return None
            out.append(RegisterRead(t, unit, fc, addr, count, error="exception",
                                    exception_code=code))
        else:
            out.append(RegisterRead(t, unit, fc, addr, count, error="timeout"))
    return out


def _answered_reads(recs: list[tuple[str, ...]]) -> list[RegisterRead] | None:
    """:func:`_fast_modbus_reads` when every record holds words (no timeout, no
    exception: a healthy module's recording), column by column: the few distinct
    ``(unit, fc, addr, count)`` checked once each, the times and words by ``map`` (the
    record-by-record loop was two thirds of reading such a file). The same records and
    the same refusals (None) as the loop."""
    ts, us, fs, As, cs, regs_s, _codes = zip(*recs, strict=True)
    times = list(map(float, ts))
    if not _times_ok(times):
        return None
    heads: dict[tuple[str, ...], tuple[int, int, int, int]] = {}
    for key in set(zip(us, fs, As, cs, strict=True)):
        unit, fc, addr, count = map(int, key)
        if not _head_ok(unit, fc, addr, count):
            return None
        heads[key] = (unit, fc, addr, count)
    blocks = map(heads.__getitem__, zip(us, fs, As, cs, strict=True))
    units, fcs, addrs, counts = zip(*blocks, strict=True)
    regs = [tuple(map(int, r.split(","))) for r in regs_s]
    if not (all(map(operator.eq, map(len, regs), counts))
            and max(map(max, regs)) <= 65535):
        return None
    return list(map(RegisterRead, times, units, fcs, addrs, counts, regs))


@dataclass
class RegisterColumns:
    """A Modbus recording in which every record answered the same block (a healthy
    module's recording, polled over and over) as columns: the records
    :func:`read_modbus_reads` yields, without a :class:`RegisterRead` and a tuple of
    Python ints per poll (they were two thirds of reading such a file, which the fast
    replay turns into arrays again)."""

    unit: int
    function: int
    address: int
    count: int
    times: list[float]
    words: Any
    """``numpy.ndarray`` of int64, one row of ``count`` raw words per record."""

    def read(self, i: int) -> RegisterRead:
        """Record ``i`` as :func:`read_modbus_reads` gives it."""
        return RegisterRead(self.times[i], self.unit, self.function, self.address,
                            self.count, registers=tuple(self.words[i].tolist()))


def read_modbus_columns(path: str | os.PathLike[str]) -> RegisterColumns | None:
    """The file's records as :class:`RegisterColumns`, or None when it holds anything
    else (a timeout, an exception, another block, a line of another shape, a bad value:
    :func:`read_modbus_reads` reads those, and names what is wrong)."""
    return _columns(_bulk_records(Path(path), MODBUS_FORMAT, _MODBUS_LINE))


def read_modbus_recording(path: str | os.PathLike[str]
                          ) -> RegisterColumns | list[RegisterRead]:
    """The file as :class:`RegisterColumns` where it is a healthy module's recording,
    else as :func:`read_modbus_reads`' records (the same errors), the file read once
    for the whole-file paths."""
    p = Path(path)
    recs = _bulk_records(p, MODBUS_FORMAT, _MODBUS_LINE)
    cols = _columns(recs)
    if cols is not None:
        return cols
    fast = _fast_modbus_reads(p, recs) if recs is not None else None
    return fast if fast is not None else list(read_modbus_reads(p, whole_file=False))


def _columns(recs: list[tuple[str, ...]] | None) -> RegisterColumns | None:
    """:func:`read_modbus_columns` on the file's line matches."""
    if not recs or not all(r[5] for r in recs):
        return None
    ts, us, fs, As, cs, regs_s, _codes = zip(*recs, strict=True)
    heads = set(zip(us, fs, As, cs, strict=True))
    if len(heads) != 1:
        return None
    unit, fc, addr, count = map(int, heads.pop())
    times = list(map(float, ts))
    if not (_head_ok(unit, fc, addr, count) and _times_ok(times)):
        return None
    import numpy as np

    # the regex let through only runs of 1-6 digits between commas, so every word is
    # parsed; the size check below still catches a record of another length
    words = np.fromstring(",".join(regs_s), dtype=np.int64, sep=",")
    if words.size != len(recs) * count or int(words.max()) > 65535:
        return None
    return RegisterColumns(unit, fc, addr, count, times, words.reshape(len(recs), count))


def read_serial_chunks(path: str | os.PathLike[str], whole_file: bool = True
                       ) -> Iterator[SerialChunk]:
    """Yield the chunks of a ``*.serial.jsonl`` file in file (= time) order
    (``whole_file=False``: line by line only, as a file of other line shapes is read)."""
    p = Path(path)
    fast = _fast_serial_chunks(p) if whole_file else None
    if fast is not None:
        yield from fast
        return
    for lineno, obj, t in _records(p, SERIAL_FORMAT):
        d = obj.get("d")
        if d not in ("rx", "tx"):
            raise CaptureFormatError(p, lineno, f"'d' must be \"rx\" or \"tx\", got {d!r}")
        hx = obj.get("hex")
        if not isinstance(hx, str):
            raise CaptureFormatError(p, lineno, "'hex' must be a string of hex digits")
        try:
            data = bytes.fromhex(hx)
        except ValueError:
            raise CaptureFormatError(p, lineno, "'hex' is not an even-length string of hex "
                                     f"digits: {hx[:40]!r}") from None
        yield SerialChunk(t, d, data)


def _int(path: Path, lineno: int, obj: dict[str, Any], key: str, lo: int, hi: int) -> int:
    v = obj.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise CaptureFormatError(path, lineno, f"'{key}' must be an integer in [{lo}, {hi}], "
                                 f"got {v!r}")
    return v


def read_modbus_reads(path: str | os.PathLike[str], whole_file: bool = True
                      ) -> Iterator[RegisterRead]:
    """Yield the register reads of a ``*.modbus.jsonl`` file in time order
    (``whole_file=False``: line by line only, as a file of other line shapes is read)."""
    p = Path(path)
    fast = _fast_modbus_reads(p) if whole_file else None
    if fast is not None:
        yield from fast
        return
    for lineno, obj, t in _records(p, MODBUS_FORMAT):
        unit = _int(p, lineno, obj, "unit", 0, 255)
        fc = _int(p, lineno, obj, "fc", 3, 4)
        addr = _int(p, lineno, obj, "addr", 0, 65535)
        count = _int(p, lineno, obj, "count", 1, 125)
        if "regs" in obj:
            regs = obj["regs"]
            if not isinstance(regs, list) or len(regs) != count or not all(
                    isinstance(r, int) and not isinstance(r, bool) and 0 <= r <= 65535
                    for r in regs):
                raise CaptureFormatError(p, lineno, f"'regs' must be a list of {count} integers "
                                         "in [0, 65535] (raw 16-bit register words)")
            yield RegisterRead(t, unit, fc, addr, count, registers=tuple(regs))
        elif obj.get("error") == "timeout":
            yield RegisterRead(t, unit, fc, addr, count, error="timeout")
        elif obj.get("error") == "exception":
            code = _int(p, lineno, obj, "code", 1, 255)
            yield RegisterRead(t, unit, fc, addr, count, error="exception",
                               exception_code=code)
        else:
            raise CaptureFormatError(p, lineno, "a record needs 'regs', or 'error': \"timeout\", "
                                     "or 'error': \"exception\" with 'code'")


def read_can_messages(path: str | os.PathLike[str], start_unix: float
                      ) -> Iterator[tuple[float, Any]]:
    """Yield ``(capture_time, can.Message)`` from a python-can readable log file.

    The file type follows python-can's :class:`can.LogReader` (``.log`` candump,
    ``.asc``, ``.blf``, ``.csv``); the writer uses candump ``.log``.
    """
    import can

    p = Path(path)
    if not p.exists():
        raise CaptureFormatError(p, None, "file missing")
    try:
        reader = can.LogReader(str(p))
    except Exception as e:  # noqa: BLE001 - python-can raises many types here
        raise CaptureFormatError(p, None, f"python-can cannot read it: {e}") from None
    n = 0
    prev = -math.inf
    try:
        for msg in reader:
            n += 1
            t = float(msg.timestamp) - start_unix
            if t < prev - 1e-6:
                raise CaptureFormatError(p, n, f"message {n} goes back in time ({t:.6f} s "
                                         f"after {prev:.6f} s)")
            prev = t
            yield t, msg
    except CaptureFormatError:
        raise
    except Exception as e:  # noqa: BLE001
        raise CaptureFormatError(p, n + 1, f"python-can cannot parse message {n + 1}: {e}"
                                 ) from None
    finally:
        stop = getattr(reader, "stop", None)
        if stop is not None:
            stop()


def read_capture(path: str | os.PathLike[str]) -> Capture:
    """Open a capture folder: check ``manifest.json`` and that every recording exists."""
    root = Path(path)
    mpath = root / "manifest.json"
    if not root.is_dir():
        raise CaptureFormatError(root, None, "not a directory (a capture is a folder)")
    try:
        text = mpath.read_text(encoding="utf-8")
    except OSError as e:
        raise CaptureFormatError(mpath, None, f"cannot read: {e.strerror}") from None
    try:
        m = json.loads(text)
    except json.JSONDecodeError as e:
        raise CaptureFormatError(mpath, e.lineno, f"not valid JSON: {e.msg}") from None
    if not isinstance(m, dict):
        raise CaptureFormatError(mpath, 1, "expected a JSON object")
    if m.get("format") != FORMAT_NAME:
        raise CaptureFormatError(mpath, None, f"'format' is {m.get('format')!r}; expected "
                                 f"{FORMAT_NAME!r}")
    if m.get("version") != FORMAT_VERSION:
        raise CaptureFormatError(mpath, None, f"'version' is {m.get('version')!r}; this reader "
                                 f"understands {FORMAT_VERSION}")
    devs = m.get("devices")
    if not isinstance(devs, dict) or not devs:
        raise CaptureFormatError(mpath, None, "'devices' must be a non-empty object")
    out: dict[str, DeviceEntry] = {}
    for name, d in devs.items():
        if not isinstance(d, dict):
            raise CaptureFormatError(mpath, None, f"devices.{name} must be an object")
        kind, fname = d.get("kind"), d.get("file")
        if kind not in KINDS:
            raise CaptureFormatError(mpath, None, f"devices.{name}.kind is {kind!r}; expected "
                                     f"one of {sorted(KINDS)}")
        if not isinstance(fname, str) or "/" in fname or fname.startswith("."):
            raise CaptureFormatError(mpath, None, f"devices.{name}.file must be a file name "
                                     "inside the capture folder")
        if not (root / fname).is_file():
            raise CaptureFormatError(mpath, None, f"devices.{name}.file {fname!r} does not exist")
        settings = {k: v for k, v in d.items() if k not in ("kind", "file")}
        cfg = settings.get("config")
        if kind == "mti_serial" and isinstance(cfg, dict):
            from drivers.xsens.serial_driver import RECORDED_BEFORE_EXTRAS

            # a key the manifest does not name was recorded at the driver's default of
            # the day: Euler angles alone (until 2026-11-26), with the rate of turn,
            # acceleration and status word (until 2026-11-29)
            settings["config"] = {"orientation": "euler",
                                  "extra_outputs": list(RECORDED_BEFORE_EXTRAS), **cfg}
        out[name] = DeviceEntry(name, kind, fname, settings)
    start = m.get("start_unix", 0.0)
    if isinstance(start, bool) or not isinstance(start, int | float):
        raise CaptureFormatError(mpath, None, f"'start_unix' must be a number, got {start!r}")
    return Capture(root, m, out)


# --------------------------------------------------------------------------- writing


class _LineFile:
    """A JSON-lines file written from several threads, flushed about once a second."""

    def __init__(self, path: Path, header: dict[str, Any]) -> None:
        self.path = path
        self._f = open(path, "w", encoding="utf-8", newline="\n")
        self._lock = threading.Lock()
        self._last_flush = time.monotonic()
        self.records = 0
        self.last_t = 0.0
        self._write(header)

    def _write(self, obj: dict[str, Any]) -> None:
        line = json.dumps(obj, separators=(",", ":"))
        with self._lock:
            if self._f.closed:
                return
            self._f.write(line + "\n")
            now = time.monotonic()
            if now - self._last_flush > _FLUSH_EVERY_S:
                self._f.flush()
                self._last_flush = now

    def close(self) -> None:
        with self._lock:
            if not self._f.closed:
                self._f.close()


class SerialRecorder:
    """Writes one serial device's traffic; also a :class:`~drivers.capture.tap.ByteTap`."""

    def __init__(self, path: Path, device: str, clock: Callable[[], float],
                 port: str | None = None, baudrate: int | None = None) -> None:
        self._file = _LineFile(path, {"format": SERIAL_FORMAT, "version": 1, "device": device,
                                      "port": port, "baudrate": baudrate})
        self._clock = clock
        self._lock = threading.Lock()
        self._prev = 0.0

    def chunk(self, t: float, direction: str, data: bytes) -> None:
        if not data:
            return
        with self._lock:  # keep the file time-ordered even across rx/tx threads
            t = max(t, self._prev)
            self._prev = t
            self._file._write({"t": round(t, 6), "d": direction, "hex": data.hex()})
            self._file.records += 1
            self._file.last_t = t

    def rx(self, data: bytes) -> None:
        self.chunk(self._clock(), "rx", data)

    def tx(self, data: bytes) -> None:
        self.chunk(self._clock(), "tx", data)

    @property
    def last_t(self) -> float:
        return self._file.last_t

    def close(self) -> None:
        self._file.close()


class ModbusRecorder:
    """Writes one Modbus device's register reads (a driver's ``register_log`` hook)."""

    def __init__(self, path: Path, device: str, clock: Callable[[], float]) -> None:
        self._file = _LineFile(path, {"format": MODBUS_FORMAT, "version": 1, "device": device})
        self._clock = clock
        self._lock = threading.Lock()
        self._prev = 0.0

    def __call__(self, read: RegisterRead) -> None:
        """Log ``read``, stamped now on the capture clock (``read.t`` is the driver's)."""
        with self._lock:
            d = read.to_json()
            d["t"] = round(max(self._clock(), self._prev), 6)
            self._prev = d["t"]
            self._file._write(d)
            self._file.records += 1
            self._file.last_t = d["t"]

    @property
    def last_t(self) -> float:
        return self._file.last_t

    def close(self) -> None:
        self._file.close()


class CanRecorder:
    """Writes one CAN device's frames through python-can's own :class:`can.Logger`."""

    def __init__(self, path: Path, start_unix: float, clock: Callable[[], float]) -> None:
        import can

        self._logger = can.Logger(str(path))
        self._start_unix = start_unix
        self._clock = clock
        self._lock = threading.Lock()
        self.last_t = 0.0

    def __call__(self, msg: Any, t: float | None = None) -> None:
        """Log ``msg`` at capture time ``t`` (default: now on the capture clock)."""
        import copy

        t = self._clock() if t is None else t
        m = copy.copy(msg)
        m.timestamp = self._start_unix + t
        with self._lock:
            self._logger.on_message_received(m)
            self.last_t = max(self.last_t, t)

    def close(self) -> None:
        with self._lock:
            self._logger.stop()


def _jsonable(v: Any) -> Any:
    if is_dataclass(v) and not isinstance(v, type):
        return asdict(v)
    return v


class CaptureWriter:
    """Creates a capture folder and hands out one recorder per device.

    The manifest is written when the writer opens (so an interrupted recording is
    still readable) and rewritten with ``duration_s`` on :meth:`close`.
    ``clock`` is the capture clock's source (seconds, any origin); capture time is
    ``clock() - clock()_at_open``.
    """

    def __init__(self, out_dir: str | os.PathLike[str], *, installation: Any = None,
                 source: str = "shoveld record", clock: Callable[[], float] = time.monotonic,
                 start_unix: float | None = None, time_origin: float | None = None,
                 overwrite: bool = False) -> None:
        self.path = Path(out_dir)
        if self.path.exists() and any(self.path.iterdir()) and not overwrite:
            raise FileExistsError(f"{self.path} exists and is not empty")
        self.path.mkdir(parents=True, exist_ok=True)
        self._clock = clock
        self._t0 = clock() if time_origin is None else time_origin
        self.start_unix = time.time() if start_unix is None else start_unix
        self.manifest: dict[str, Any] = {
            "format": FORMAT_NAME, "version": FORMAT_VERSION,
            "start_unix": round(self.start_unix, 6),
            "start_utc": _dt.datetime.fromtimestamp(self.start_unix, _dt.UTC).isoformat(),
            "source": source,
            "installation": _jsonable(installation) if installation is not None else None,
            "devices": {},
        }
        self._recorders: list[Any] = []
        self._write_manifest()

    def now(self) -> float:
        """Capture time (seconds since the capture started)."""
        return self._clock() - self._t0

    def _add(self, name: str, kind: str, fname: str, settings: dict[str, Any]) -> None:
        if kind not in KINDS:
            raise ValueError(f"device {name!r}: kind {kind!r} not one of {sorted(KINDS)}")
        if name in self.manifest["devices"]:
            raise ValueError(f"device {name!r} added twice")
        self.manifest["devices"][name] = {"kind": kind, "file": fname, **settings}
        self._write_manifest()

    def add_serial(self, name: str, kind: str, *, port: str | None, baudrate: int | None,
                   config: dict[str, Any] | None = None) -> SerialRecorder:
        fname = f"{name}.serial.jsonl"
        self._add(name, kind, fname, {"port": port, "baudrate": baudrate,
                                      "config": config or {}})
        rec = SerialRecorder(self.path / fname, name, self.now, port, baudrate)
        self._recorders.append(rec)
        return rec

    def add_modbus(self, name: str, kind: str, *, config: dict[str, Any]) -> ModbusRecorder:
        fname = f"{name}.modbus.jsonl"
        self._add(name, kind, fname, {"config": config})
        rec = ModbusRecorder(self.path / fname, name, self.now)
        self._recorders.append(rec)
        return rec

    def add_can(self, name: str, kind: str, *, channel: str | None, interface: str | None,
                bitrate: int | None, config: dict[str, Any] | None = None) -> CanRecorder:
        fname = f"{name}.can.log"
        self._add(name, kind, fname, {"channel": channel, "interface": interface,
                                      "bitrate": bitrate, "config": config or {}})
        rec = CanRecorder(self.path / fname, self.start_unix, self.now)
        self._recorders.append(rec)
        return rec

    def set_meta(self, key: str, value: Any) -> None:
        """Add a top-level manifest entry (e.g. ``signals_table`` for synthetic captures)."""
        self.manifest[key] = _jsonable(value)
        self._write_manifest()

    def _write_manifest(self) -> None:
        tmp = self.path / "manifest.json.tmp"
        tmp.write_text(json.dumps(self.manifest, indent=2) + "\n", encoding="utf-8")
        os.replace(tmp, self.path / "manifest.json")

    def close(self, duration_s: float | None = None) -> None:
        for r in self._recorders:
            r.close()
        self.manifest["duration_s"] = round(self.now() if duration_s is None else duration_s, 6)
        self._write_manifest()

    def __enter__(self) -> CaptureWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
