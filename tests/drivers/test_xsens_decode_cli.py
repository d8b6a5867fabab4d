"""``shoveld decode mti``: JSON lines per MTData2 message, counters on stderr."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import pytest

from drivers.xsens.mtdata2 import FP1220, NWU, XDI, encode_mtdata2
from drivers.xsens.xbus import MID, encode_frame
from shoveld.cli import main

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "xsens-mti-g710"


def test_decodes_a_real_capture(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["decode", "mti", str(FIXTURES / "1" / "output.bin")]) == 0
    out, err = capsys.readouterr()
    objs = [json.loads(line) for line in out.splitlines()]
    assert len(objs) == 100
    assert objs[0]["packet_counter"] == 43398 and objs[0]["sample_time_fine"] == 51703123
    assert objs[0]["acceleration"] == [-0.017374228686094284, -7.255744934082031,
                                       -1.209552526473999]
    assert objs[1]["euler_deg"] == [-99.46182250976562, 0.13305406272411346,
                                    -179.1905975341797]
    assert objs[1]["status"] == 0b101
    assert "100 messages (100 MTData2), 0 rejected bytes, 0 bad frames" in err


def test_every_key_any_precision_from_stdin(monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    payload = encode_mtdata2([
        (XDI.PACKET_COUNTER, 9), (XDI.SAMPLE_TIME_FINE, 100),
        (XDI.EULER_ANGLES | NWU | FP1220, (1.0, 2.0, 3.0)),
        (XDI.QUATERNION | FP1220, (1.0, 0.0, 0.0, 0.0)),
        (XDI.ACCELERATION | 3, (0.0, 0.0, 9.81)), (XDI.RATE_OF_TURN | 2, (0.5, 0.0, -0.5)),
        (XDI.MAGNETIC_FIELD, (0.25, 0.5, -1.0)), (XDI.TEMPERATURE | 3, (31.5,)),
        (XDI.STATUS_WORD, 3), (0x9990, b"??")])
    stream = (b"junk" + encode_frame(MID.MTDATA2, payload) + encode_frame(MID.ERROR, b"\x04")
              + encode_frame(MID.MTDATA2, payload)[:-3])
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(stream)))
    assert main(["decode", "mti", "-", "--all"]) == 0
    out, err = capsys.readouterr()
    lines = [json.loads(x) for x in out.splitlines()]
    assert lines[0] == {"packet_counter": 9, "sample_time_fine": 100,
                        "euler_deg": [1.0, 2.0, 3.0], "quaternion": [1.0, 0.0, 0.0, 0.0],
                        "acceleration": [0.0, 0.0, 9.81], "rate_of_turn": [0.5, 0.0, -0.5],
                        "magnetic_field": [0.25, 0.5, -1.0], "temperature": 31.5, "status": 3}
    assert lines[1]["name"] == "Error" and "invalid message" in lines[1]["error"]
    assert "2 messages (1 MTData2)" in err
    assert "1 bad frame" in err and "1 bad frames" not in err
    assert f"{4 + len(payload) + 5 - 3} rejected bytes" in err


def test_missing_file_is_a_one_line_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["decode", "mti", "/nonexistent.bin"]) == 2
    assert "cannot read /nonexistent.bin" in capsys.readouterr().err


def test_a_file_with_no_xbus_message_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                 ) -> None:
    """A wrong file (here a capture's JSON lines, which hold the stream as hex) or an
    empty one said "0 messages" and exited 0 (until 2026-11-30): now one line, exit 2."""
    from pathlib import Path

    capture = (Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures"
               / "daemon-e2e" / "mti.serial.jsonl")
    assert main(["decode", "mti", str(capture)]) == 2
    out = capsys.readouterr()
    assert out.out == ""
    assert out.err.strip() == (f"shoveld decode: error: {capture}: "
                               f"{capture.stat().st_size} bytes and not one Xbus message: "
                               "expected an Xsens MTi's raw byte stream (of a capture, the "
                               "bytes of its rx lines' hex)")
    empty = tmp_path / "empty.bin"
    empty.write_bytes(b"")
    assert main(["decode", "mti", str(empty)]) == 2
    assert f"{empty}: no byte:" in capsys.readouterr().err
