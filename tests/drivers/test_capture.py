"""Capture format: write/read round trips, hand-written captures, reader errors, clock."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import can
import pytest

from drivers.capture import CaptureFormatError, CaptureWriter, ReplayClock, read_capture
from drivers.capture.format import (
    RegisterRead,
    SerialChunk,
    read_modbus_columns,
    read_modbus_reads,
    read_serial_chunks,
)
from drivers.capture.replay import RecordedAnswers, RecordedRegisters, split_answers
from shoveld.installation import Installation


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def write_sample(path: Path) -> None:
    clock = FakeClock()
    w = CaptureWriter(path, installation=Installation(crowd_offset_m=6.0), clock=clock,
                      start_unix=1_700_000_000.0)
    ser = w.add_serial("laser", "ar4000", port="/dev/ttyS1", baudrate=9600,
                       config={"kind": "ar4000", "port": "/dev/ttyS1"})
    mb = w.add_modbus("adc", "modbus_tcp", config={"kind": "modbus_tcp", "host": "10.0.0.5"})
    cn = w.add_can("mti", "mti_can", channel="can0", interface="socketcan", bitrate=1_000_000)
    clock.t = 100.001
    ser.tx(b"A4\r")
    clock.t = 100.0105
    ser.rx(b"1234\r\n\x00\xff")
    mb(RegisterRead(0.0, 1, 4, 0, 3, registers=(1, 65535, 32768)))
    clock.t = 100.02
    mb(RegisterRead(0.0, 1, 4, 0, 3, error="timeout"))
    mb(RegisterRead(0.0, 1, 4, 0, 3, error="exception", exception_code=4))
    cn(can.Message(arbitration_id=0x22, data=b"\x01\x02\x03\x04\x05\x06", is_extended_id=False))
    clock.t = 100.5
    w.close()


def test_round_trip(tmp_path: Path) -> None:
    write_sample(tmp_path / "cap")
    cap = read_capture(tmp_path / "cap")
    m = cap.manifest
    assert m["format"] == "shoveld-capture" and m["version"] == 1
    assert m["duration_s"] == pytest.approx(0.5)
    assert m["installation"]["crowd_offset_m"] == 6.0
    assert cap.devices["laser"].settings["baudrate"] == 9600
    assert list(cap.serial_chunks("laser")) == [
        # approx stands for the recorded time: it compares equal to a float near it
        SerialChunk(pytest.approx(0.001), "tx", b"A4\r"),  # type: ignore[arg-type]
        SerialChunk(pytest.approx(0.0105), "rx", b"1234\r\n\x00\xff")]  # type: ignore[arg-type]
    reads = list(cap.modbus_reads("adc"))
    assert [r.registers for r in reads] == [(1, 65535, 32768), None, None]
    assert [r.error for r in reads] == [None, "timeout", "exception"]
    assert reads[2].exception_code == 4 and reads[1].t == pytest.approx(0.02)
    (t, msg), = list(cap.can_messages("mti"))
    assert t == pytest.approx(0.02, abs=1e-5)
    assert msg.arbitration_id == 0x22 and bytes(msg.data) == b"\x01\x02\x03\x04\x05\x06"
    assert cap.duration_s() == pytest.approx(0.5)


def test_can_log_is_readable_by_python_can_itself(tmp_path: Path) -> None:
    write_sample(tmp_path / "cap")
    msgs = list(can.LogReader(str(tmp_path / "cap" / "mti.can.log")))
    assert len(msgs) == 1 and msgs[0].timestamp == pytest.approx(1_700_000_000.02, abs=1e-5)


def test_a_capture_written_by_hand_from_the_docs(tmp_path: Path) -> None:
    """Follows docs/captures.md literally, without any shoveld code."""
    d = tmp_path / "hand"
    d.mkdir()
    (d / "manifest.json").write_text(json.dumps({
        "format": "shoveld-capture", "version": 1, "start_unix": 1700000000.0,
        "devices": {
            "laser": {"kind": "ar4000", "file": "laser.serial.jsonl",
                      "config": {"port": "/dev/ttyS1", "units": "mm"}},
            "adc": {"kind": "modbus_rtu", "file": "adc.modbus.jsonl", "config": {}},
            "mti": {"kind": "mti_can", "file": "mti.can.log", "channel": "can0"}}}))
    (d / "laser.serial.jsonl").write_text(
        '{"format": "shoveld-serial-chunks", "version": 1}\n'
        '{"t": 0.0, "d": "rx", "hex": "313233340d0a"}\n'
        '{"t": 0.02, "d": "rx", "hex": "300D0A"}\n')
    (d / "adc.modbus.jsonl").write_text(
        '{"format": "shoveld-modbus-reads", "version": 1}\n'
        '{"t": 0.01, "unit": 1, "fc": 4, "addr": 0, "count": 2, "regs": [100, 65436]}\n'
        '{"t": 0.03, "unit": 1, "fc": 4, "addr": 0, "count": 2, "error": "timeout"}\n')
    (d / "mti.can.log").write_text("(1700000000.010000) can0 022#000005010A00\n")
    cap = read_capture(d)
    assert b"".join(c.data for c in cap.serial_chunks("laser")) == b"1234\r\n0\r\n"
    assert [r.error for r in cap.modbus_reads("adc")] == [None, "timeout"]
    assert [t for t, _ in cap.can_messages("mti")] == [pytest.approx(0.01)]


def _serial(d: Path, lines: list[str]) -> Path:
    p = d / "x.serial.jsonl"
    p.write_text("\n".join(['{"format": "shoveld-serial-chunks", "version": 1}'] + lines) + "\n")
    return p


@pytest.mark.parametrize("line, text", [
    ('{"t": 0.1, "d": "rx", "hex": "zz"}', "'hex' is not an even-length string"),
    ('{"t": 0.1, "d": "in", "hex": "00"}', "'d' must be"),
    ('{"t": "0.1", "d": "rx", "hex": "00"}', "'t' must be a finite number"),
    ('{"t": 0.1, "d": "rx"', "not valid JSON"),
    ('[1, 2]', "expected a JSON object"),
    ('{"t": 0.01, "d": "rx", "hex": "00"}', "goes back in time"),
])
def test_serial_reader_errors_name_file_and_line(tmp_path: Path, line: str, text: str) -> None:
    p = _serial(tmp_path, ['{"t": 0.05, "d": "rx", "hex": "00"}', line])
    with pytest.raises(CaptureFormatError) as e:
        list(read_serial_chunks(p))
    assert str(e.value).startswith(f"{p}:3: ") and text in str(e.value)


def test_header_errors(tmp_path: Path) -> None:
    from drivers.capture.format import read_modbus_reads

    p = tmp_path / "a.serial.jsonl"
    p.write_text('{"format": "shoveld-modbus-reads", "version": 1}\n')
    with pytest.raises(CaptureFormatError, match=r"a.serial.jsonl:1: header 'format'"):
        list(read_serial_chunks(p))
    p.write_text("")
    with pytest.raises(CaptureFormatError, match="empty file"):
        list(read_serial_chunks(p))
    q = tmp_path / "b.modbus.jsonl"
    q.write_text('{"format": "shoveld-modbus-reads", "version": 2}\n')
    with pytest.raises(CaptureFormatError, match=r"b.modbus.jsonl:1: header 'version'"):
        list(read_modbus_reads(q))
    q.write_text('{"format": "shoveld-modbus-reads", "version": 1}\n'
                 '{"t": 1, "unit": 1, "fc": 4, "addr": 0, "count": 2, "regs": [1]}\n')
    with pytest.raises(CaptureFormatError, match=r"b.modbus.jsonl:2: 'regs' must be a list of 2"):
        list(read_modbus_reads(q))
    q.write_text('{"format": "shoveld-modbus-reads", "version": 1}\n'
                 '{"t": 1, "unit": 1, "fc": 6, "addr": 0, "count": 2, "regs": [1, 2]}\n')
    with pytest.raises(CaptureFormatError, match=r":2: 'fc' must be an integer in \[3, 4\]"):
        list(read_modbus_reads(q))
    q.write_text('{"format": "shoveld-modbus-reads", "version": 1}\n'
                 '{"t": 1, "unit": 1, "fc": 4, "addr": 0, "count": 2}\n')
    with pytest.raises(CaptureFormatError, match=r":2: a record needs 'regs'"):
        list(read_modbus_reads(q))


def test_manifest_errors(tmp_path: Path) -> None:
    with pytest.raises(CaptureFormatError, match="not a directory"):
        read_capture(tmp_path / "nope")
    d = tmp_path / "c"
    d.mkdir()
    with pytest.raises(CaptureFormatError, match="manifest.json: cannot read"):
        read_capture(d)
    (d / "manifest.json").write_text('{"format": "shoveld-capture", "version": 1,\n "devices": ')
    with pytest.raises(CaptureFormatError, match=r"manifest.json:2: not valid JSON"):
        read_capture(d)
    base = {"format": "shoveld-capture", "version": 1}
    for devices, text in [({}, "'devices' must be a non-empty object"),
                          ({"l": {"kind": "laser", "file": "l.serial.jsonl"}}, "devices.l.kind"),
                          ({"l": {"kind": "ar4000", "file": "../x"}}, "devices.l.file must"),
                          ({"l": {"kind": "ar4000", "file": "l.serial.jsonl"}}, "does not exist")]:
        (d / "manifest.json").write_text(json.dumps({**base, "devices": devices}))
        with pytest.raises(CaptureFormatError, match=text):
            read_capture(d)
    (d / "manifest.json").write_text(json.dumps({**base, "version": 7}))
    with pytest.raises(CaptureFormatError, match="'version' is 7"):
        read_capture(d)


def test_writer_refuses_a_non_empty_folder(tmp_path: Path) -> None:
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "f").write_text("")
    with pytest.raises(FileExistsError):
        CaptureWriter(tmp_path / "x")
    with pytest.raises(ValueError, match="kind 'laser'"):
        CaptureWriter(tmp_path / "y").add_serial("l", "laser", port=None, baudrate=None)


# --------------------------------------------------------------------------- replay parts


def test_split_answers_and_recorded_answers() -> None:
    chunks = [SerialChunk(0.0, "rx", b"early"), SerialChunk(0.1, "tx", b"A4\r"),
              SerialChunk(0.11, "rx", b"ack1"), SerialChunk(0.12, "tx", b"S10\r"),
              SerialChunk(0.13, "rx", b"ack2"), SerialChunk(0.5, "rx", b"stream"),
              SerialChunk(1.0, "tx", b"A4\r"), SerialChunk(1.01, "rx", b"ack3")]
    stream, pairs = split_answers(chunks, 0.05)
    assert stream == [(0.0, b"early"), (0.5, b"stream")]
    assert pairs == [(b"A4\r", b"ack1"), (b"S10\r", b"ack2"), (b"A4\r", b"ack3")]
    r = RecordedAnswers(pairs)
    assert r(b"A") is None  # partial write: wait for the rest
    assert r(b"4\rS10\r") == b"ack1ack2"
    assert r(b"A4\r") == b"ack3"
    assert r(b"A4\r") == b"ack3"  # the last answer repeats
    assert r(b"unknown") is None


def test_recorded_registers_follow_capture_time() -> None:
    now = {"t": 0.0}
    reads = [RegisterRead(0.1, 1, 4, 0, 2, registers=(1, 2)),
             RegisterRead(0.2, 1, 4, 0, 2, error="timeout"),
             RegisterRead(0.3, 1, 4, 0, 2, error="exception", exception_code=6),
             RegisterRead(0.4, 1, 4, 0, 2, registers=(3, 4))]
    rr = RecordedRegisters(reads, lambda: now["t"])
    assert rr(4, 0, 2) == 6  # before the first record: DEVICE_BUSY, not an invented value
    now["t"] = 0.1
    assert rr(4, 0, 2) == [1, 2]
    now["t"] = 0.25
    assert rr(4, 0, 2) is None  # recorded timeout -> silence
    now["t"] = 0.35
    assert rr(4, 0, 2) == 6
    now["t"] = 9.0
    assert rr(4, 0, 2) == [3, 4] and rr(4, 1, 1) == [4]
    assert rr(4, 5, 1) == 2 and rr(3, 0, 2) == 2  # never recorded -> illegal address


def test_recorded_registers_of_two_blocks_interleaved() -> None:
    now = {"t": 0.0}
    reads = [RegisterRead(0.1, 1, 4, 0, 2, registers=(1, 2)),
             RegisterRead(0.1, 1, 4, 8, 1, registers=(9,)),
             RegisterRead(0.2, 1, 4, 0, 2, registers=(3, 4)),
             RegisterRead(0.3, 1, 4, 8, 1, error="timeout")]
    rr = RecordedRegisters(reads, lambda: now["t"])
    assert rr.end_t == 0.3
    assert rr.recorded((4, 0, 2)) == [reads[0], reads[2]]
    assert rr.recorded((4, 8, 1)) == [reads[1], reads[3]]
    now["t"] = 0.25
    assert rr(4, 0, 2) == [3, 4] and rr(4, 8, 1) == [9]
    now["t"] = 0.3
    assert rr(4, 8, 1) is None
    one = RecordedRegisters(reads[::2], lambda: 0.2)
    assert one.recorded((4, 0, 2)) == reads[::2] and one.end_t == 0.2
    assert RecordedRegisters([], lambda: 0.0).end_t == 0.0


def test_replay_clock_paced() -> None:
    c = ReplayClock(10.0, speed=4.0)
    time.sleep(0.05)
    assert 10.15 < c() < 10.6
    assert c.wait_until(c.now() + 0.2, timeout=1.0)
    with pytest.raises(RuntimeError):
        c.advance(1.0)
    with pytest.raises(ValueError):
        ReplayClock(speed=0)


def test_replay_clock_stepped_waits_for_settle_checks() -> None:
    c = ReplayClock(0.0, speed=None, settle_timeout_s=0.2)
    seen: list[float] = []

    def settled(t: float) -> bool:
        seen.append(t)
        return len(seen) > 2
    c.add_settle_check(settled)
    assert c.advance(0.5) == 0.5 and c() == 0.5 and len(seen) == 3
    c.add_settle_check(lambda t: False)
    t0 = time.monotonic()
    c.advance_to(0.4)  # never backwards
    assert c() == 0.5 and c.unsettled_steps == 1 and time.monotonic() - t0 >= 0.2
    # a waiter wakes when the consumer advances past its time
    woke: list[bool] = []
    th = threading.Thread(target=lambda: woke.append(c.wait_until(0.6, timeout=2.0)))
    th.start()
    time.sleep(0.05)
    assert not woke
    c.settle_timeout_s = 0.0
    c.advance(0.2)
    th.join()
    assert woke == [True]


def test_stepped_advance_waits_for_released_waiters_to_finish_their_step() -> None:
    c = ReplayClock(0.0, speed=None, settle_timeout_s=2.0)
    done: list[float] = []
    stop = threading.Event()

    def poller() -> None:  # like a driver polling every 0.1 s of capture time
        nxt = 0.1
        while not stop.is_set():
            if c.wait_until(nxt, timeout=0.05):
                time.sleep(0.05)  # the poll's real work
                done.append(nxt)
                nxt += 0.1

    th = threading.Thread(target=poller)
    th.start()
    time.sleep(0.05)
    c.advance(0.05)
    assert done == []
    c.advance(0.05)  # releases the 0.1 poll: returns only after its work
    assert done == [pytest.approx(0.1)]
    c.advance(0.1)
    assert len(done) == 2
    stop.set()
    th.join()


def _split_reference(chunks: list[SerialChunk], window: float
                     ) -> tuple[list[tuple[float, bytes]], list[tuple[bytes, bytes]]]:
    """split_answers as it was written first: a bisect for every rx chunk."""
    import bisect

    txs = [c for c in chunks if c.direction == "tx"]
    tx_times = [c.t for c in txs]
    stream: list[tuple[float, bytes]] = []
    answers = [bytearray() for _ in txs]
    for c in chunks:
        if c.direction != "rx":
            continue
        i = bisect.bisect_right(tx_times, c.t) - 1
        if i >= 0 and c.t - tx_times[i] <= window:
            answers[i] += c.data
        else:
            stream.append((c.t, c.data))
    return stream, [(txs[i].data, bytes(answers[i])) for i in range(len(txs))]


@pytest.mark.parametrize("seed", range(12))
def test_split_answer_columns_agree_with_a_bisect_per_chunk(seed: int) -> None:
    """Writes early, late, in bursts, none at all; chunks on and around the window's
    edge (times that round either way), equal times; the committed MTi recording."""
    import random

    from drivers.capture.format import read_serial_chunks
    from drivers.capture.replay import split_answer_columns

    rng = random.Random(seed)
    if seed == 11:
        cap = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures" / "daemon-e2e"
        chunks = list(read_serial_chunks(cap / "mti.serial.jsonl"))
    else:
        t, chunks = rng.uniform(0, 50), []
        for _ in range(rng.randrange(0, 400)):
            r = rng.random()
            if r < 0.1:
                t += 0.0  # an equal time
            elif r < 0.3:
                t = t + 0.05 + rng.choice([-1e-16, 0.0, 1e-16, 1e-12])  # on the edge
            else:
                t += rng.uniform(0, 0.2)
            d = "tx" if rng.random() < (0.3 if seed % 3 == 0 else 0.05) else "rx"
            chunks.append(SerialChunk(t, d, rng.randbytes(rng.randrange(0, 5))))
    cols = [c.t for c in chunks], [c.direction for c in chunks], [c.data for c in chunks]
    st, sd, pairs = split_answer_columns(*cols, 0.05)
    stream, ref_pairs = _split_reference(chunks, 0.05)
    assert list(zip(st, sd, strict=True)) == stream and pairs == ref_pairs
    assert split_answers(chunks, 0.05) == (stream, ref_pairs)


def test_recorded_registers_answer_alike_from_columns(tmp_path: Path) -> None:
    """The replay's register answers are the same whether the recording was read as
    records or as columns: latest answer, a block inside the recorded one, before the
    first read, and an address never recorded."""
    body = "".join(
        f'{{"t":{t},"unit":1,"fc":4,"addr":10,"count":3,"regs":[{t * 10:.0f},7,{65535 - i}]}}\n'
        for i, t in enumerate((0.1, 0.2, 0.2, 0.5)))
    p = tmp_path / "m.modbus.jsonl"
    p.write_text('{"format":"shoveld-modbus-reads","version":1,"device":"m"}\n' + body)
    cols = read_modbus_columns(p)
    assert cols is not None
    now = {"t": 0.0}
    a = RecordedRegisters(cols, lambda: now["t"])
    b = RecordedRegisters(list(read_modbus_reads(p)), lambda: now["t"])
    assert a.end_t == b.end_t == 0.5
    assert a.columns((4, 10, 3)) is cols and b.columns((4, 10, 3)) is None
    assert a.columns((4, 10, 2)) is None
    assert a.recorded((4, 10, 3)) == b.recorded((4, 10, 3))
    for t in (0.0, 0.1, 0.15, 0.2, 0.49, 0.5, 9.0):
        now["t"] = t
        for block in ((4, 10, 3), (4, 11, 2), (4, 10, 1), (4, 0, 1), (3, 10, 3)):
            assert a(*block) == b(*block), (t, block)
    now["t"] = 0.2
    assert a(4, 10, 3) == [2, 7, 65533]  # the later of the two reads at 0.2
