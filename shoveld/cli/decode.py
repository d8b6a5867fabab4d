"""``shoveld decode KIND FILE``: turn a raw device byte stream into one JSON object per message.

For looking at what a device really sent (a capture from the field, a serial sniff),
independent of the daemon. Each device kind is one entry of :data:`DECODERS`: a name,
a help line, an optional function adding its own options, and the function that
decodes a binary stream. Adding ``decode ar4000`` is adding one :class:`Decoder`.

``decode mti`` reads an Xsens Xbus stream and prints every MTData2 message, whatever
its precision (float32, fp12.20, fp16.32, float64) or coordinate frame, with the keys
that apply: packet_counter, sample_time_fine, euler_deg, quaternion, acceleration,
rate_of_turn, magnetic_field, temperature, status. Counters of rejected bytes and bad
frames go to stderr at the end.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, BinaryIO, TextIO

from shoveld.cli import CliError
from shoveld.words import n_of

CHUNK = 1 << 16


@dataclass(frozen=True)
class Decoder:
    """One ``decode`` sub-choice."""

    name: str
    help: str
    run: Callable[[BinaryIO, TextIO, TextIO, argparse.Namespace], int]
    add_arguments: Callable[[argparse.ArgumentParser], None] | None = None


def _mti_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--all", action="store_true",
                   help="also print non-MTData2 messages as {mid, name, data_hex}")


def _num(v: float | int) -> str:
    """JSON text of a number; repr is valid JSON for finite floats and ~3x cheaper."""
    r = repr(v)
    return r if r not in ("nan", "inf", "-inf") else json.dumps(v)


def decode_mti(src: BinaryIO, out: TextIO, err: TextIO, args: argparse.Namespace) -> int:
    """Decode an Xbus byte stream; print MTData2 messages as JSON lines."""
    from drivers.xsens.mtdata2 import XDI, mtdata2_values
    from drivers.xsens.xbus import MID, MID_NAMES, XbusParser, describe_error

    fields = (("packet_counter", XDI.PACKET_COUNTER), ("sample_time_fine", XDI.SAMPLE_TIME_FINE),
              ("euler_deg", XDI.EULER_ANGLES), ("quaternion", XDI.QUATERNION),
              ("acceleration", XDI.ACCELERATION), ("rate_of_turn", XDI.RATE_OF_TURN),
              ("magnetic_field", XDI.MAGNETIC_FIELD), ("temperature", XDI.TEMPERATURE),
              ("status", XDI.STATUS_WORD), ("status", XDI.STATUS_BYTE))
    show_all = bool(getattr(args, "all", False))
    parser = XbusParser()
    n_msgs = n_data = 0
    while True:
        chunk = src.read(CHUNK)
        if not chunk:
            break
        lines = []
        for msg in parser.feed(chunk):
            n_msgs += 1
            if msg.mid == MID.MTDATA2:
                n_data += 1
                vals = mtdata2_values(msg.data)
                parts = []
                seen = set()
                for key, xdi in fields:
                    v = vals.get(xdi)
                    if v is None or key in seen:
                        continue
                    seen.add(key)
                    if key == "temperature":
                        v = v[0]
                    if isinstance(v, tuple):
                        parts.append(f'"{key}": [{", ".join(map(_num, v))}]')
                    else:
                        parts.append(f'"{key}": {_num(v)}')
                lines.append("{" + ", ".join(parts) + "}")
            elif show_all:
                o: dict[str, Any] = {"mid": msg.mid, "name": MID_NAMES.get(msg.mid, "?"),
                                     "data_hex": msg.data.hex()}
                if msg.mid == MID.ERROR:
                    o["error"] = describe_error(msg.data)
                lines.append(json.dumps(o))
        if lines:
            out.write("\n".join(lines) + "\n")
    parser.finish()
    if n_msgs == 0:
        # a wrong file (a capture's JSON lines, a laser's log) said so, not "0 messages"
        # and success
        name = getattr(src, "name", "-")
        name = "stdin" if not isinstance(name, str) or name == "<stdin>" else name
        got = (n_of(parser.rejected_bytes, "byte", "bytes") + " and not one Xbus message"
               if parser.rejected_bytes else "no byte")
        raise CliError(f"{name}: {got}: expected an Xsens MTi's raw byte stream (of a "
                       "capture, the bytes of its rx lines' hex)")
    print(f"decode mti: {n_of(n_msgs, 'message', 'messages')} ({n_data} MTData2), "
          f"{n_of(parser.rejected_bytes, 'rejected byte', 'rejected bytes')}, "
          f"{n_of(parser.bad_frames, 'bad frame', 'bad frames')}", file=err)
    return 0


DECODERS: tuple[Decoder, ...] = (
    Decoder("mti", "Xsens MTi Xbus byte stream (MTData2 to JSON lines)", decode_mti,
            _mti_arguments),
)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "decode", help="decode a raw device byte stream to JSON lines",
        description="Decode a raw device byte stream (a capture or a serial sniff) into one "
                    "JSON object per message on stdout; counters on stderr.")
    kinds = p.add_subparsers(dest="kind", metavar="KIND", required=True)
    for d in DECODERS:
        k = kinds.add_parser(d.name, help=d.help, description=d.help)
        k.add_argument("file", metavar="FILE", help="raw byte stream; '-' for stdin")
        if d.add_arguments is not None:
            d.add_arguments(k)
        k.set_defaults(func=run, decoder=d)


def run(args: argparse.Namespace) -> int:
    decoder: Decoder = args.decoder
    if args.file == "-":
        return decoder.run(sys.stdin.buffer, sys.stdout, sys.stderr, args)
    try:
        f = open(args.file, "rb")
    except OSError as e:
        raise CliError(f"cannot read {args.file}: {e.strerror}") from None
    with f:
        return decoder.run(f, sys.stdout, sys.stderr, args)
