"""``shoveld estimate``: payload per pass and per truck from signals tables."""

from __future__ import annotations

import argparse
import json
import sys

from shoveld.cli import CliError
from shoveld.cli.common import check_output, read_params, read_tables, refuse_repeats
from shoveld.cli.options import KG, SECONDS
from shoveld.payload.misfit import misfit_note


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "estimate", help="estimate the payload of every pass in signals tables",
        description="Runs the live engine over each table: dig-cycle phases, recursive "
                    "least squares over lift and swing, final at the dump. One line per "
                    "pass, then the trucks against the target and the 10/10/20 rule.")
    p.add_argument("files", nargs="+", metavar="FILE")
    p.add_argument("--params", required=True, help="params file from 'shoveld calibrate'")
    p.add_argument("--json", action="store_true",
                   help="one JSON object per pass on stdout; the truck summary as JSON "
                        "on stderr")
    p.add_argument("--truck-target", type=KG, default=136000.0, help="kg per truck")
    p.add_argument("--truck-gap", type=SECONDS, default=20.0,
                   help="a pause without digging this long (s) starts a new truck")
    p.add_argument("--plot", metavar="PNG",
                   help="plot phases, live payload and passes (one file per table: "
                        "PNG gets the table's name inserted when there are several)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from shoveld.engine.loop import EngineConfig
    from shoveld.engine.offline import estimate_table
    from shoveld.payload.trucks import rule_101020, rule_summary, truck_line

    if args.plot:
        check_output(args.plot)  # (a folder was written to as FOLDER/.png)
    refuse_repeats(args.files)
    params = read_params(args.params)
    tables = read_tables(args.files)
    cfg = EngineConfig(truck_target_kg=args.truck_target, truck_gap_s=args.truck_gap)
    next_pass, next_truck = 1, 1
    trucks = []
    for table in tables:
        est = estimate_table(table, params, cfg, next_pass, next_truck,
                             keep_live=bool(args.plot))
        if args.plot:
            from pathlib import Path

            from shoveld.plots import plot_estimate

            out = Path(args.plot)
            if len(tables) > 1:
                out = out.with_name(f"{out.stem}-{Path(table.source).stem}{out.suffix}")
            try:
                print(f"plot: {plot_estimate(table, est, out)}", file=sys.stderr)
            except RuntimeError as e:
                raise CliError(str(e)) from None
        for p in est.passes:
            d = {**p.as_dict(), "file": table.source}
            if args.json:
                print(json.dumps(d))
            elif p.valid:
                print(f"pass {p.index:3d}  truck {p.truck:3d}  {p.start_s:9.1f}-{p.end_s:9.1f} s"
                      f"  {p.payload_kg:9.0f} kg +- {p.std_kg:5.0f} kg  ({table.source})"
                      f"{misfit_note(d['misfit'], cfg.misfit_warn)}")
            else:
                print(f"pass {p.index:3d}  truck {p.truck:3d}  {p.start_s:9.1f}-{p.end_s:9.1f} s"
                      f"  INVALID: {p.reason}  ({table.source})"
                      f"{misfit_note(d['misfit'], cfg.misfit_warn)}")
        if est.passes:
            next_pass = est.passes[-1].index + 1
        else:  # said, not left as an empty answer (a trial, a shift without digging)
            span = float(table.time[-1] - table.time[0])  # a table has a row at least
            print(f"{table.source}: no pass (no dig followed by a lift and a swing in its "
                  f"{span:.0f} s)", file=sys.stderr)
        if est.trucks:
            next_truck = est.trucks[-1].index + 1
        trucks.extend(est.trucks)
    rule = rule_101020(trucks)
    summary = {"trucks": [t.as_dict() for t in trucks], "rule_10_10_20": rule}
    if args.json:
        print(json.dumps(summary), file=sys.stderr)
    elif trucks:
        print()
        for t in trucks:
            print(f"truck {t.index:3d}: {truck_line(t.as_dict())}")
        print(f"10/10/20 over {rule_summary(rule, closed=False)}")
    return 0
