"""The capture readers' whole-file path reads what the line-by-line path reads.

The recorder's line shapes are matched over the whole file at once; a file with any
other line must be read (or refused, with its line named) exactly as the line-by-line
reader does. Each case is read both ways and compared.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

import drivers.capture.format as fmt

CAPTURES = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures"
SERIAL_HEAD = '{"format":"shoveld-serial-chunks","version":1,"device":"x"}\n'
MODBUS_HEAD = '{"format":"shoveld-modbus-reads","version":1,"device":"x"}\n'


def _outcome(read: Callable[..., Iterator[Any]], path: Path, whole_file: bool
             ) -> tuple[list[Any], str]:
    """Records read before any error, and the error's text ('' if none)."""
    got: list[Any] = []
    try:
        for r in read(path, whole_file):
            got.append(r)
    except fmt.CaptureFormatError as e:
        return got, str(e)
    return got, ""


def _both_ways(read: Callable[..., Iterator[Any]], path: Path) -> tuple[Any, Any]:
    return _outcome(read, path, True), _outcome(read, path, False)


def _serial_file(tmp_path: Path, body: str) -> Path:
    """A serial recording of ``body``'s lines under the recorder's header."""
    p = tmp_path / "x.serial.jsonl"
    p.write_bytes((SERIAL_HEAD + body).encode())
    return p


def _modbus_file(tmp_path: Path, body: str) -> Path:
    """A Modbus recording of ``body``'s lines under the recorder's header."""
    p = tmp_path / "x.modbus.jsonl"
    p.write_bytes((MODBUS_HEAD + body).encode())
    return p


@pytest.mark.parametrize("path", sorted(CAPTURES.glob("*/*.jsonl")), ids=lambda p: p.name)
def test_committed_recordings_read_alike(path: Path) -> None:
    read = fmt.read_serial_chunks if path.name.endswith(".serial.jsonl") else \
        fmt.read_modbus_reads
    assert fmt._bulk_records(path, fmt.SERIAL_FORMAT if read is fmt.read_serial_chunks
                             else fmt.MODBUS_FORMAT,
                             fmt._SERIAL_LINE if read is fmt.read_serial_chunks
                             else fmt._MODBUS_LINE) is not None  # the fast path is taken
    whole, by_line = _both_ways(read, path)
    assert whole == by_line and whole[0] and not whole[1]


SERIAL_CASES = {
    "canonical": '{"t":0.5,"d":"rx","hex":"0a0B"}\n{"t":1,"d":"tx","hex":""}\n',
    "spaces": '{"t": 0.5, "d": "rx", "hex": "0a"}\n',
    "two objects on a line": '{"t":0.5,"d":"rx","hex":"0a"},{"t":0.6,"d":"rx","hex":"0a"}\n',
    "odd hex": '{"t":0.5,"d":"rx","hex":"0a0"}\n',
    "back in time": '{"t":0.5,"d":"rx","hex":"0a"}\n{"t":0.4,"d":"rx","hex":"0a"}\n',
    "huge exponent": '{"t":1e400,"d":"rx","hex":"0a"}\n',
    "torn last line": '{"t":0.5,"d":"rx","hex":"0a"}\n{"t":0.6,"d":"rx","he',
    "no final newline": '{"t":0.5,"d":"rx","hex":"0a"}',
    "blank lines": '\n{"t":0.5,"d":"rx","hex":"0a"}\n  \n{"t":0.7,"d":"tx","hex":"0b"}\n',
    "leading zero": '{"t":00.5,"d":"rx","hex":"0a"}\n',
    "crlf": '{"t":0.5,"d":"rx","hex":"0a"}\r\n',
    "other direction": '{"t":0.5,"d":"xx","hex":"0a"}\n',
}
MODBUS_CASES = {
    "canonical": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":2,"regs":[0,65535]}\n'
                 '{"t":0.2,"unit":1,"fc":4,"addr":0,"count":2,"error":"timeout"}\n'
                 '{"t":0.3,"unit":1,"fc":3,"addr":9,"count":2,"error":"exception","code":4}\n',
    "wrong count": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":3,"regs":[0,1]}\n',
    "word too big": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":1,"regs":[65536]}\n',
    "unit too big": '{"t":0.1,"unit":256,"fc":4,"addr":0,"count":1,"regs":[1]}\n',
    "function 5": '{"t":0.1,"unit":1,"fc":5,"addr":0,"count":1,"regs":[1]}\n',
    "code 0": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":1,"error":"exception","code":0}\n',
    "count 0": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":0,"regs":[1]}\n',
    "other error": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":1,"error":"crc"}\n',
}


@pytest.mark.parametrize("name", sorted(SERIAL_CASES))
def test_serial_files_read_alike(name: str, tmp_path: Path) -> None:
    p = _serial_file(tmp_path, SERIAL_CASES[name])
    whole, by_line = _both_ways(fmt.read_serial_chunks, p)
    assert whole == by_line


@pytest.mark.parametrize("name", sorted(MODBUS_CASES))
def test_modbus_files_read_alike(name: str, tmp_path: Path) -> None:
    p = _modbus_file(tmp_path, MODBUS_CASES[name])
    whole, by_line = _both_ways(fmt.read_modbus_reads, p)
    assert whole == by_line


def _columns_outcome(path: Path) -> tuple[Any, str]:
    try:
        return fmt.read_serial_columns(path), ""
    except fmt.CaptureFormatError as e:
        return None, str(e)


def _columns_of(path: Path) -> tuple[Any, str]:
    """The line-by-line reader's chunks as columns, or its error."""
    got, err = _outcome(fmt.read_serial_chunks, path, False)
    if err:
        return None, err
    return ([c.t for c in got], [c.direction for c in got], [c.data for c in got]), ""


@pytest.mark.parametrize("path", sorted(CAPTURES.glob("*/*.serial.jsonl")),
                         ids=lambda p: p.name)
def test_committed_serial_recordings_read_alike_as_columns(path: Path) -> None:
    cols, err = _columns_outcome(path)
    assert not err and cols[0] and (cols, err) == _columns_of(path)
    assert fmt._fast_serial_columns(path) is not None  # the whole-file path was taken


@pytest.mark.parametrize("name", sorted(SERIAL_CASES))
def test_serial_files_read_alike_as_columns(name: str, tmp_path: Path) -> None:
    p = _serial_file(tmp_path, SERIAL_CASES[name])
    assert _columns_outcome(p) == _columns_of(p)


ANSWERED_CASES = {
    "two blocks": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":2,"regs":[0,65535]}\n'
                  '{"t":0.1,"unit":1,"fc":3,"addr":8,"count":1,"regs":[7]}\n'
                  '{"t":0.2,"unit":1,"fc":4,"addr":0,"count":2,"regs":[1,2]}\n',
    "back in time": '{"t":0.2,"unit":1,"fc":4,"addr":0,"count":1,"regs":[1]}\n'
                    '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":1,"regs":[1]}\n',
    "one short answer": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":2,"regs":[1,2]}\n'
                        '{"t":0.2,"unit":1,"fc":4,"addr":0,"count":2,"regs":[1]}\n',
    "a word too big later": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":1,"regs":[1]}\n'
                            '{"t":0.2,"unit":1,"fc":4,"addr":0,"count":1,"regs":[70000]}\n',
    "a bad block later": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":1,"regs":[1]}\n'
                         '{"t":0.2,"unit":300,"fc":4,"addr":0,"count":1,"regs":[1]}\n',
    "count 126": '{"t":0.1,"unit":1,"fc":4,"addr":0,"count":126,"regs":['
                 + ",".join(["1"] * 126) + "]}\n",
    "huge time": '{"t":1e999,"unit":1,"fc":4,"addr":0,"count":1,"regs":[1]}\n',
    "empty": "",
}


@pytest.mark.parametrize("name", sorted(ANSWERED_CASES))
def test_modbus_files_of_answers_only_read_alike(name: str, tmp_path: Path) -> None:
    """Files where every record holds words take the column-by-column path."""
    p = _modbus_file(tmp_path, ANSWERED_CASES[name])
    whole, by_line = _both_ways(fmt.read_modbus_reads, p)
    assert whole == by_line


def _as_columns(path: Path) -> list[fmt.RegisterRead] | None:
    """The records of :func:`fmt.read_modbus_columns`, or None where it declines."""
    cols = fmt.read_modbus_columns(path)
    return None if cols is None else [cols.read(i) for i in range(len(cols.times))]


@pytest.mark.parametrize("path", sorted(CAPTURES.glob("*/*.modbus.jsonl")),
                         ids=lambda p: f"{p.parent.name}/{p.name}")
def test_committed_modbus_recordings_read_alike_as_columns(path: Path) -> None:
    """A healthy module's recording (one block, every poll answered) is read as columns,
    record for record what the line-by-line reader gives."""
    got = _as_columns(path)
    assert got is not None and got == _outcome(fmt.read_modbus_reads, path, False)[0]


COLUMN_CASES = {**{f"mixed {k}": v for k, v in MODBUS_CASES.items()}, **ANSWERED_CASES,
                "one block": '{"t":0.1,"unit":2,"fc":3,"addr":7,"count":2,"regs":[0,65535]}\n'
                             '{"t":0.1,"unit":2,"fc":3,"addr":7,"count":2,"regs":[5,6]}\n'
                             '{"t":0.3,"unit":2,"fc":3,"addr":7,"count":2,"regs":[12,0]}\n'}


@pytest.mark.parametrize("name", sorted(COLUMN_CASES))
def test_modbus_columns_are_the_records_or_declined(name: str, tmp_path: Path) -> None:
    """Columns are given only for a file of one block whose every record is a valid
    answer, and then hold exactly its records; anything else (a timeout, an exception,
    another block, a bad value, a torn line) is left to the reads, which name it."""
    p = _modbus_file(tmp_path, COLUMN_CASES[name])
    got = _as_columns(p)
    records, err = _outcome(fmt.read_modbus_reads, p, False)
    one_block = len({(r.unit, r.function, r.address, r.count) for r in records}) == 1
    answered = all(r.registers is not None for r in records)
    if err or not records or not one_block or not answered:
        assert got is None
    else:
        assert got == records
    if name == "one block":
        assert got is not None and len(got) == 3


@pytest.mark.parametrize("name", sorted(COLUMN_CASES))
def test_a_modbus_recording_is_its_records_in_either_form(name: str, tmp_path: Path) -> None:
    """What the replay reads (``read_modbus_recording``: columns where they apply, else
    the records, the file matched once) is what the line-by-line reader gives, or its
    error."""
    p = _modbus_file(tmp_path, COLUMN_CASES[name])
    records, err = _outcome(fmt.read_modbus_reads, p, False)
    try:
        got = fmt.read_modbus_recording(p)
    except fmt.CaptureFormatError as e:
        assert err and str(e) == err
        return
    assert not err
    if isinstance(got, fmt.RegisterColumns):
        got = [got.read(i) for i in range(len(got.times))]
        assert len({(r.unit, r.function, r.address, r.count) for r in records}) == 1
        assert all(r.registers is not None for r in records)
    assert got == records
