"""Long fuzz run of the Xbus parser and MTData2 decoder (the test suite runs 300 examples).

Each example is a stream of valid frames (MTData2 with known and unknown data
identifiers, other messages, extended lengths), random garbage, truncated frames and
flipped bits, fed in random chunks. For every example it checks that nothing raises,
that every returned frame occurs verbatim (checksum included) in the input, in order,
that every byte is accounted for (frames + rejected + pending), and that each MTData2
payload decodes without error. Prints the example count, time and result.

Two generators: a plain seeded ``random`` one (fast; ``--examples``, default 200,000)
and Hypothesis (``--hypothesis N``; slower per example but it shrinks a failure to a
minimal stream).

    .venv/bin/python bench/fuzz_xsens.py [--examples 200000] [--hypothesis 2000] [--seed 1]
"""

from __future__ import annotations

import argparse
import random
import sys
import time

from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

from drivers.xsens.mtdata2 import ITEM_TYPES, decode_mtdata2, mtdata2_values
from drivers.xsens.xbus import XbusParser, checksum_ok, encode_frame

COUNT = {"examples": 0, "frames": 0, "bytes": 0}

xdi_st = st.one_of(st.sampled_from(sorted(ITEM_TYPES)), st.integers(0, 0xFFFF)).flatmap(
    lambda t: st.integers(0, 15).map(lambda low: (t & 0xFFF0) | low))
packet_st = st.tuples(xdi_st, st.binary(max_size=40)).map(
    lambda xb: xb[0].to_bytes(2, "big") + bytes((len(xb[1]),)) + xb[1])
mtdata2_st = st.lists(packet_st, max_size=10).map(b"".join)
frame_st = st.one_of(
    mtdata2_st.map(lambda p: encode_frame(0x36, p)),
    st.tuples(st.integers(0, 255), st.binary(max_size=300)).map(lambda md: encode_frame(*md)))
part_st = st.one_of(frame_st, st.binary(max_size=60),
                    frame_st.map(lambda f: f[:len(f) // 2]))


@st.composite
def streams(draw: st.DrawFn) -> tuple[bytes, list[bytes]]:
    data = bytearray(b"".join(draw(st.lists(part_st, max_size=12))))
    for _ in range(draw(st.integers(0, 3))):
        if data:
            k = draw(st.integers(0, len(data) - 1))
            data[k] ^= 1 << draw(st.integers(0, 7))
    stream = bytes(data)
    cuts = sorted(draw(st.lists(st.integers(0, len(stream)), max_size=6)))
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    return stream, chunks


def check(stream: bytes, chunks: list[bytes]) -> None:
    p = XbusParser()
    out = []
    for c in chunks:
        out += p.feed(c)
    pos = consumed = 0
    for m in out:
        f = encode_frame(m.mid, m.data)
        assert checksum_ok(f)
        k = stream.find(f, pos)
        if k < 0:  # a short payload sent in the (valid) extended length form
            f = encode_frame(m.mid, m.data, extended=True)
            k = stream.find(f, pos)
        assert k >= 0, "returned a frame that is not in the input"
        pos = k + len(f)
        consumed += len(f)
        if m.mid == 0x36:
            decode_mtdata2(m.data)
            mtdata2_values(m.data)
    assert consumed + p.rejected_bytes + p.pending == len(stream)
    p.finish()
    assert consumed + p.rejected_bytes == len(stream)
    COUNT["examples"] += 1
    COUNT["frames"] += len(out)
    COUNT["bytes"] += len(stream)


XDIS = sorted(ITEM_TYPES)


def random_stream(rng: random.Random) -> tuple[bytes, list[bytes]]:
    """The same mixture as the Hypothesis strategy, from a plain PRNG."""
    def payload() -> bytes:
        out = b""
        for _ in range(rng.randint(0, 10)):
            t = rng.choice(XDIS) if rng.random() < 0.8 else rng.randrange(0x10000)
            xdi = (t & 0xFFF0) | rng.randrange(16)
            body = rng.randbytes(rng.choice((rng.randint(0, 40), 4, 12, 24, 18, 36, 94)))
            out += xdi.to_bytes(2, "big") + bytes((len(body),)) + body
        return out

    def frame() -> bytes:
        if rng.random() < 0.6:
            return encode_frame(0x36, payload())
        return encode_frame(rng.randrange(256), rng.randbytes(rng.choice(
            (rng.randint(0, 30), rng.randint(250, 600)))))

    parts = []
    for _ in range(rng.randint(0, 12)):
        r = rng.random()
        if r < 0.5:
            parts.append(frame())
        elif r < 0.8:
            parts.append(rng.randbytes(rng.randint(0, 60)))
        else:
            f = frame()
            parts.append(f[:rng.randint(0, len(f) - 1)])
    data = bytearray(b"".join(parts))
    for _ in range(rng.randint(0, 3)):
        if data:
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    stream = bytes(data)
    cuts = sorted(rng.randint(0, len(stream)) for _ in range(rng.randint(0, 6)))
    return stream, [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--examples", type=int, default=200_000, help="plain random examples")
    ap.add_argument("--hypothesis", type=int, default=0, help="Hypothesis examples")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    t0 = time.perf_counter()
    rng = random.Random(args.seed)
    try:
        for _ in range(args.examples):
            check(*random_stream(rng))
    except Exception as e:  # noqa: BLE001 - report any failure with the example
        print(f"fuzz_xsens: random example {COUNT['examples'] + 1} FAILED: "
              f"{type(e).__name__}: {e}")
        return 1
    dt = time.perf_counter() - t0
    print(f"fuzz_xsens random: {COUNT['examples']} examples ({COUNT['frames']} frames, "
          f"{COUNT['bytes'] / 1e6:.1f} MB) in {dt:.0f} s, seed {args.seed}: OK: no crash, "
          "no invented or bad-checksum frame, every byte accounted for")
    if not args.hypothesis:
        return 0
    for k in COUNT:
        COUNT[k] = 0

    @seed(args.seed)
    @settings(max_examples=args.hypothesis, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(streams())
    def fuzz(sc: tuple[bytes, list[bytes]]) -> None:
        check(*sc)

    t0 = time.perf_counter()
    try:
        fuzz()
        result = "OK: no crash, no invented or bad-checksum frame, every byte accounted for"
        rc = 0
    except Exception as e:  # noqa: BLE001 - report any failure with the example
        result = f"FAILED: {type(e).__name__}: {e}"
        rc = 1
    dt = time.perf_counter() - t0
    print(f"fuzz_xsens hypothesis: {COUNT['examples']} examples ({COUNT['frames']} frames, "
          f"{COUNT['bytes'] / 1e6:.1f} MB) in {dt:.0f} s, seed {args.seed}: {result}")
    return rc


if __name__ == "__main__":
    sys.exit(main())
