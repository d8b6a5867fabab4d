"""Xbus framing: encoder, message ids, streaming parser, resynchronisation, fuzzing.

The parser must never invent a frame (every frame it returns occurs, checksum and
all, in the input), must account for every byte, and must recover the next good frame
after garbage, a bad checksum or a truncated frame.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.sniffer import PacketSniffer
from drivers.xsens.xbus import (
    ERROR_CODES,
    MID,
    XbusMessage,
    XbusParser,
    checksum_ok,
    describe_error,
    encode_frame,
)

EXAMPLES = 300


def test_message_ids_match_vendor_values() -> None:
    assert (MID.GOTO_CONFIG, MID.GOTO_CONFIG_ACK) == (0x30, 0x31)
    assert (MID.GOTO_MEASUREMENT, MID.GOTO_MEASUREMENT_ACK) == (0x10, 0x11)
    assert (MID.REQ_DID, MID.DEVICE_ID) == (0x00, 0x01)
    assert (MID.REQ_FW_REV, MID.FIRMWARE_REV) == (0x12, 0x13)
    assert (MID.SET_OUTPUT_CONFIGURATION, MID.OUTPUT_CONFIGURATION) == (0xC0, 0xC1)
    assert (MID.WAKEUP, MID.WAKEUP_ACK) == (0x3E, 0x3F)
    assert (MID.ERROR, MID.MTDATA2) == (0x42, 0x36)


def test_encoder_matches_documented_examples() -> None:
    # ReqDID = FA FF 00 00 01 is the MTi user manual's example; the rest follow its rule.
    assert encode_frame(MID.REQ_DID) == bytes.fromhex("faff000001")
    assert encode_frame(MID.GOTO_CONFIG) == bytes.fromhex("faff3000d1")
    assert encode_frame(MID.GOTO_MEASUREMENT) == bytes.fromhex("faff1000f1")
    assert encode_frame(MID.WAKEUP_ACK) == bytes.fromhex("faff3f00c2")


def test_checksum_low_byte_of_sum_after_preamble_is_zero() -> None:
    for n in (0, 1, 17, 254, 255, 256, 1000):
        f = encode_frame(0x36, bytes(k & 0xFF for k in range(n)))
        assert sum(f[1:]) & 0xFF == 0 and checksum_ok(f)


def test_extended_length_round_trip() -> None:
    data = bytes(k * 7 & 0xFF for k in range(600))
    f = encode_frame(0x36, data)
    assert f[3] == 0xFF and (f[4] << 8 | f[5]) == 600 and len(f) == 600 + 7
    assert XbusParser().feed(f) == [XbusMessage(0x36, data)]
    short = encode_frame(0x36, bytes(254))
    assert short[3] == 254 and len(short) == 259
    forced = encode_frame(0x36, b"abc", extended=True)  # legal: extended form, short data
    assert forced[3:6] == b"\xff\x00\x03" and checksum_ok(forced)
    assert XbusParser().feed(forced) == [XbusMessage(0x36, b"abc")]


def test_error_codes_are_described() -> None:
    assert ERROR_CODES[0x04].startswith("invalid message")
    assert "0x21" in describe_error(b"\x21") and "invalid parameter" in describe_error(b"\x21")
    assert "DSP crashed" in describe_error(b"\x28\x00\x00\x00\x06")
    assert "unknown" in describe_error(b"\x99")


def frames(*msgs: tuple[int, bytes]) -> bytes:
    return b"".join(encode_frame(m, d) for m, d in msgs)


GOOD = [(0x36, bytes(range(40))), (0x31, b""), (0x01, b"\x06\x30\x12\x34"), (0x36, b"\xfa\xff")]


def test_resync_after_garbage_bad_checksum_and_truncation() -> None:
    good = frames(*GOOD)
    bad = bytearray(encode_frame(0x36, bytes(30)))
    bad[10] ^= 0x01
    truncated = encode_frame(0x36, bytes(range(100)))[:50]
    stream = b"\x00\x12\xfa\x34" + bytes(bad) + truncated + good + b"\xfa"
    p = XbusParser()
    out = p.feed(stream)
    assert out == [XbusMessage(m, d) for m, d in GOOD]
    assert p.bad_frames >= 2 and p.pending == 1
    assert p.rejected_bytes + p.pending + len(good) == len(stream)
    p.finish()
    assert p.rejected_bytes + len(good) == len(stream)


def test_preamble_inside_payload_and_split_preamble() -> None:
    msgs = [(0x36, b"\xfa\xff\x36\x02\x00\x00"), (0x36, b"\xfa")]
    stream = frames(*msgs)
    p = XbusParser()
    out = []
    for b in stream:
        out += p.feed(bytes((b,)))
    assert out == [XbusMessage(m, d) for m, d in msgs]
    assert p.rejected_bytes == 0


def test_absurd_extended_length_is_not_waited_for() -> None:
    p = XbusParser(max_payload=2048)
    good = encode_frame(0x36, b"abc")
    out = p.feed(b"\xfa\xff\x36\xff\xff\xff" + good)
    assert out == [XbusMessage(0x36, b"abc")]


def test_other_bus_ids_are_garbage() -> None:
    f = bytearray(encode_frame(0x36, b"xy"))
    f[1] = 0x01
    f[-1] = (-sum(f[1:-1])) & 0xFF
    p = XbusParser()
    assert p.feed(bytes(f)) == [] and p.rejected_bytes == len(f)


def test_sniffer_generic_use_and_bounds() -> None:
    def measure(buf: bytearray, i: int) -> int:
        j = buf.find(b"\n", i)
        return 0 if j < 0 else j + 1 - i

    s = PacketSniffer(b"$", measure, max_pending=16)
    assert s.feed(b"xx$A,1\n$B") == [b"$A,1\n"]
    assert s.feed(b",2\n") == [b"$B,2\n"]
    assert s.rejected_bytes == 2
    s.feed(b"$" + b"z" * 40)
    assert s.pending <= 16


# --- property tests (hypothesis) -------------------------------------------------------

frame_st = st.tuples(st.integers(0, 255), st.binary(max_size=300)).map(
    lambda md: encode_frame(*md))


def check_invariants(stream: bytes, chunks: list[bytes] | None = None) -> list[XbusMessage]:
    p = XbusParser()
    out: list[XbusMessage] = []
    for c in (chunks if chunks is not None else [stream]):
        out += p.feed(c)
    consumed = 0
    pos = 0
    for m in out:
        f = encode_frame(m.mid, m.data)
        assert checksum_ok(f)
        k = stream.find(f, pos)
        if k < 0:  # a short payload sent in the (valid) extended length form
            f = encode_frame(m.mid, m.data, extended=True)
            k = stream.find(f, pos)
        assert k >= 0, "parser returned a frame that is not in the input"
        pos = k + len(f)
        consumed += len(f)
    assert consumed + p.rejected_bytes + p.pending == len(stream)
    p.finish()
    assert consumed + p.rejected_bytes == len(stream)
    return out


@settings(max_examples=EXAMPLES, deadline=None)
@given(st.binary(max_size=2000))
def test_random_garbage_never_crashes_or_invents_frames(data: bytes) -> None:
    check_invariants(data)


@settings(max_examples=EXAMPLES, deadline=None)
@given(st.lists(st.one_of(frame_st, st.binary(max_size=40),
                          frame_st.map(lambda f: f[:len(f) // 2])), max_size=12))
def test_mixture_of_frames_garbage_and_truncated_frames(parts: list[bytes]) -> None:
    check_invariants(b"".join(parts))


@settings(max_examples=EXAMPLES, deadline=None)
@given(st.lists(frame_st, min_size=1, max_size=8), st.data())
def test_flipped_bits_never_yield_bad_frames(fs: list[bytes], data: st.DataObject) -> None:
    stream = bytearray(b"".join(fs))
    for _ in range(data.draw(st.integers(1, 4))):
        k = data.draw(st.integers(0, len(stream) - 1))
        stream[k] ^= 1 << data.draw(st.integers(0, 7))
    check_invariants(bytes(stream))


@settings(max_examples=EXAMPLES, deadline=None)
@given(st.lists(frame_st, max_size=8),
       st.lists(st.binary(max_size=30).map(lambda b: b.replace(b"\xfa", b"\x00")), max_size=9))
def test_every_good_frame_is_recovered_between_garbage(fs: list[bytes], junk: list[bytes]
                                                       ) -> None:
    parts: list[bytes] = []
    for k, f in enumerate(fs):
        parts += [junk[k] if k < len(junk) else b"", f]
    stream = b"".join(parts)
    out = check_invariants(stream)
    assert [encode_frame(m.mid, m.data) for m in out] == fs


@settings(max_examples=EXAMPLES, deadline=None)
@given(st.lists(st.one_of(frame_st, st.binary(max_size=20)), max_size=8), st.data())
def test_chunking_does_not_change_the_result(parts: list[bytes], data: st.DataObject) -> None:
    stream = b"".join(parts)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    assert check_invariants(stream, chunks) == check_invariants(stream)
