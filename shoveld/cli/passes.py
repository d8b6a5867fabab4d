"""``shoveld passes``: the pass log for a shift report (table or CSV).

Reads the daemon's SQLite pass log read-only (safe while the daemon writes, thanks
to WAL). ``--since``/``--until`` take ISO dates and times (local time unless an
offset is given), Unix seconds, or a span back from now (``12h``, ``30m``, ``2d``).
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import re
import sys
import time
from pathlib import Path
from typing import Any

from shoveld.cli import CliError
from shoveld.daemon.messages import LATEST
from shoveld.payload.misfit import misfit_note


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "passes", help="export the pass log (shift report)",
        description="Lists the passes the daemon committed to its pass log, with trucks and "
                    "the 10/10/20 summary of the trucks closed in the period; --csv for a "
                    "spreadsheet.")
    add_log_window(p)
    p.add_argument("--csv", action="store_true", help="CSV on stdout")
    p.set_defaults(func=run)


def add_log_window(p: argparse.ArgumentParser) -> None:
    """Where the pass log is and which of its passes to read: the options ``passes`` and
    ``report`` share, so that both read the same log the same way (:func:`read_window`)."""
    from shoveld.paths import CONFIG_SEARCH

    src = p.add_mutually_exclusive_group()
    src.add_argument("--config", default=None,
                     help=f"daemon config whose shovel.state_dir to read (default: "
                          f"{CONFIG_SEARCH})")
    src.add_argument("--state-dir", default=None, help="the daemon's state directory")
    src.add_argument("--db", default=None, help="the pass log file itself")
    p.add_argument("--since", default=None, metavar="WHEN",
                   help="passes that ended at or after WHEN: an ISO date or time, Unix "
                        "seconds, 12h / 30m / 2d back from now, today or yesterday "
                        "(default: the whole log)")
    p.add_argument("--until", default=None, metavar="WHEN", help="... and before WHEN")


def parse_when(text: str, now: float | None = None) -> float:
    """ISO 8601 (local time if naive), Unix seconds, ``<n>[smhd]`` before now, or
    ``today`` / ``yesterday`` (local midnight); from 1970 to 9999 (a time the dates of
    the output cannot hold ended in a traceback: ``--since 99999999999999``,
    ``--since 0001-01-01``)."""
    t = _when(text, now)
    if not 0.0 <= t <= LATEST:
        raise _outside(text)
    return t


def _outside(text: str) -> CliError:
    return CliError(f"time {text!r} is outside 1970-01-01 .. 9999-12-30 (UTC)")


def _when(text: str, now: float | None) -> float:
    now = time.time() if now is None else now
    s = text.strip()
    if s.lower() in ("today", "yesterday", "now"):
        if s.lower() == "now":
            return now
        midnight = dt.datetime.fromtimestamp(now).astimezone().replace(
            hour=0, minute=0, second=0, microsecond=0)
        if s.lower() == "yesterday":
            midnight -= dt.timedelta(days=1)
        return midnight.timestamp()
    m = re.fullmatch(r"(\d+(?:\.\d+)?)\s*([smhd])", s)
    if m:
        mult = {"s": 1, "m": 60, "h": 3600, "d": 86400}[m.group(2)]
        return now - float(m.group(1)) * mult
    if re.fullmatch(r"\d{9,}(\.\d*)?", s):
        return float(s)
    try:
        d = dt.datetime.fromisoformat(s)
    except ValueError:
        raise CliError(f"cannot read time {text!r}: use e.g. 2026-11-21T18:00, 2026-11-21, "
                       "12h, yesterday, or Unix seconds of 9 digits or more") from None
    if d.tzinfo is None:
        try:
            d = d.astimezone()  # naive = local time
        except (OverflowError, ValueError):  # a date at the ends of what datetime holds
            raise _outside(text) from None
    return d.timestamp()


def iso(t: float | None) -> str:
    if t is None:
        return ""
    return dt.datetime.fromtimestamp(t).astimezone().isoformat(timespec="seconds")


def _db(args: argparse.Namespace) -> Path:
    from shoveld.daemon.config import ConfigError, load_config
    from shoveld.daemon.persist import db_path
    from shoveld.paths import find_config

    if args.db:
        return Path(args.db)
    if args.state_dir:
        return db_path(args.state_dir)
    try:
        cfg = load_config(args.config or find_config(), check_drivers=False)
    except ConfigError as e:
        raise CliError(f"{e} (or give --state-dir / --db)") from None
    return db_path(cfg.state_dir)


def read_window(args: argparse.Namespace
                ) -> tuple[list[dict[str, Any]], Path, float | None, float | None]:
    """The passes of ``--since``/``--until`` from the pass log the arguments name, the
    log's path and the window read; one line naming the file where it is not a pass log
    (``passes`` and ``report`` read alike)."""
    from shoveld.daemon.persist import read_passes

    since = parse_when(args.since) if args.since else None
    until = parse_when(args.until) if args.until else None
    if since is not None and until is not None and until <= since:
        raise CliError(f"--until {args.until!r} is not after --since {args.since!r}: the "
                       "window holds no time")
    path = _db(args)
    try:
        rows = read_passes(path, since, until)
    except FileNotFoundError as e:
        raise CliError(str(e)) from None
    except Exception as e:  # noqa: BLE001 - sqlite3.DatabaseError: not a pass log
        raise CliError(f"{path}: cannot read the pass log: {e}") from None
    return rows, path, since, until


def run(args: argparse.Namespace) -> int:
    from shoveld.payload.trucks import Truck, rule_101020, rule_summary, truck_line

    rows, path, since, until = read_window(args)
    if args.csv:
        w = csv.writer(sys.stdout, lineterminator="\n")
        w.writerow(["pass", "truck", "shovel", "start", "end", "payload_kg", "std_kg",
                    "samples", "valid", "reason", "misfit"])
        for r in rows:
            w.writerow([r["pass"], r["truck"], r["shovel"], iso(r["start"]), iso(r["end"]),
                        "" if r["payload_kg"] is None else f"{r['payload_kg']:.1f}",
                        "" if r["std_kg"] is None else f"{r['std_kg']:.1f}",
                        r["samples"], int(r["valid"]), r["reason"],
                        "" if r["misfit"] is None else f"{r['misfit']:.2f}"])
        return 0
    if not rows:
        print(f"no passes in {path}" + (f" since {iso(since)}" if since else ""))
        return 0
    for r in rows:
        val = (f"{r['payload_kg']:9.0f} kg +- {r['std_kg']:5.0f} kg" if r["valid"]
               else f"INVALID: {r['reason']}")
        print(f"pass {r['pass']:5d}  truck {r['truck']:4d}  {iso(r['start'])} .. "
              f"{iso(r['end'])[11:]}  {val}{misfit_note(r['misfit'])}")
    trucks: dict[int, Truck] = {}
    closed: dict[int, bool] = {}
    for r in rows:
        t = trucks.setdefault(r["truck"], Truck(r["truck"], r["truck_target_kg"] or 1.0))
        t.passes.append({"payload_kg": r["payload_kg"], "std_kg": r["std_kg"] or 0.0,
                         "valid": r["valid"]})
        closed[r["truck"]] = r["truck_closed"]
    print()
    for i, t in trucks.items():
        print(f"truck {i:4d}: {truck_line(t.as_dict())}{'' if closed[i] else ' (open)'}")
    if any(closed.values()):
        rule = rule_101020([t for i, t in trucks.items() if closed[i]])
        print(f"10/10/20 over {rule_summary(rule)}")
    return 0
