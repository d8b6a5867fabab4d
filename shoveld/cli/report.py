"""``shoveld report``: the shift report from the pass log, as HTML (with plots) and CSV."""

from __future__ import annotations

import argparse
from pathlib import Path

from shoveld.cli import CliError
from shoveld.words import n_of


def register(sub: argparse._SubParsersAction) -> None:
    from shoveld.cli.passes import add_log_window

    p = sub.add_parser(
        "report", help="shift report: HTML page with plots, and CSV, from the pass log",
        description="Writes DIR/index.html (one file a supervisor opens in any browser) and "
                    "the tables as CSV: tonnes per hour, trucks against target and the "
                    "10/10/20 rule, pass payloads and truck fill, cycle times, passes not "
                    "weighed and why, passes the model did not fit, the empty dipper "
                    "weighed on the returns, and a calibration that said its model lacks "
                    "something.")
    add_log_window(p)
    p.add_argument("--out", required=True, metavar="DIR", help="folder to write (created)")
    p.add_argument("--title", default="Shift report")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from shoveld.cli.common import check_output
    from shoveld.cli.passes import read_window
    from shoveld.daemon.persist import read_calibrations, read_empties
    from shoveld.report.figures import shift_figures
    from shoveld.report.write import write_report

    check_output(args.out, folder=True)
    rows, path, since, until = read_window(args)
    figures = shift_figures(rows, since, until, empties=read_empties(path, since, until),
                            calibrations=read_calibrations(path))
    try:
        page = write_report(figures, Path(args.out), args.title)
    except OSError as e:
        raise CliError(f"--out {args.out}: {e.strerror or e}") from None
    print(f"wrote {page} ({n_of(len(rows), 'pass', 'passes')}, "
          f"{n_of(len(figures.trucks), 'truck', 'trucks')}, "
          f"{figures.total_kg / 1000:.1f} t)")
    return 0
