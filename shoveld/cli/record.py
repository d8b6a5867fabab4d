"""``shoveld record``: record live devices into a capture folder (docs/captures.md).

Runs the real drivers with recording taps, so the capture holds exactly the bytes,
frames and register reads the daemon would have seen, and can be replayed through
the same drivers later.
"""

from __future__ import annotations

import argparse
import json
import signal
import threading
from typing import Any

from shoveld.cli.options import SECONDS


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "record", help="record live devices into a capture folder",
        description="Record the configured devices (TOML [devices.<name>] sections, "
                    "see docs/captures.md) into a capture folder until --duration or Ctrl-C.")
    p.add_argument("--config", required=True, help="TOML file with [devices.<name>] sections")
    p.add_argument("--out", required=True, help="capture folder to create")
    p.add_argument("--duration", type=SECONDS, default=None, metavar="S",
                   help="seconds to record (default: until interrupted)")
    p.add_argument("--overwrite", action="store_true", help="allow a non-empty --out folder")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from drivers.capture.recorder import RecordConfigError, Recorder, load_record_config
    from shoveld.cli import CliError

    try:
        config = load_record_config(args.config)
        rec = Recorder(config, args.out, overwrite=args.overwrite, where=args.config)
    except (RecordConfigError, FileExistsError) as e:
        raise CliError(str(e)) from None
    stop = threading.Event()
    old = signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        summary = rec.run(args.duration, stop)
    finally:
        signal.signal(signal.SIGINT, old)
    print(json.dumps({"capture": str(rec.writer.path), "duration_s":
                      rec.writer.manifest.get("duration_s"), "devices": summary}, indent=2))
    return 0
