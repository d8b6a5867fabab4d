"""``shoveld diagnose``: what the model gets wrong, the physical cause, and the gain."""

from __future__ import annotations

import argparse
import json
import math
import sys

from shoveld.cli import CliError
from shoveld.cli.common import check_output, parse_effects, read_tables, refuse_repeats
from shoveld.cli.options import number
from shoveld.words import n_of


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "diagnose", help="find the physical effect the model misses in measured data",
        description="Identifies the base model on the calibration trials, predicts the "
                    "measured operating data, tries every named physical extension of the "
                    "model on passes it was not fitted on, adds the ones that pay one at a "
                    "time (or none), and reports the payload gain on the scale-verified "
                    "passes. See docs/diagnosis.md.")
    p.add_argument("--calib", nargs="+", required=True, metavar="FILE",
                   help="calibration trials (empty and known-load), as for 'calibrate'")
    p.add_argument("--measured", nargs="+", required=True, metavar="FILE",
                   help="operating data; passes with payload_kg filled are scale-verified")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--report", metavar="DIR",
                   help="write report.md, plots (PNG) and extended.params.toml into DIR")
    p.add_argument("--candidates", default="", metavar="NAME,...",
                   help="limit the library of candidate extensions (default: all)")
    p.add_argument("--alpha", type=number(0.0, 1.0, lo_open=True, hi_open=True), default=0.01,
                   help="family-wise false-alarm probability per step (default 0.01)")
    p.add_argument("--min-gain", type=number(0.0, 1.0, hi_open=True), default=0.02,
                   help="smallest share of the held-out residual an effect must remove")
    p.add_argument("--max-effects", type=number(0, integer=True), default=3)
    p.add_argument("--method", choices=("output", "equation"), default="output",
                   help="output: currents as outputs, weighted by their noise (default); "
                        "equation: the thesis form, for comparison")
    p.add_argument("--no-engine", action="store_true",
                   help="skip re-running the live engine on the verified passes")
    p.set_defaults(func=run)


def _summary(js: dict) -> str:
    from shoveld.diagnose.report import added, candidate_verdict, finding_text, removals

    lines = []
    if js["found"]:
        lines.append("found: " + ", ".join(js["found"]))
        for n in js["found"]:
            lines.append(f"  {n}: {js['causes'][n]}")
            for f in js["physical"].get(n, []):
                lines.append(f"    {finding_text(f)}")
    else:
        lines.append("found: nothing significant")
    lines.append("")
    lines.append(f"{'candidate':26s} {'score':>8s} {'t':>7s} {'crit':>6s}  verdict")
    gone = removals(js["steps"])
    for c in js["ranked"]:
        # an infinite t is a candidate with nothing to fit here (a delay of zero)
        t = "n/a" if c["t"] is None or not math.isfinite(c["t"]) else f"{c['t']:.2f}"
        score = 100 * (c["score"] or 0.0)
        sc = f"{score:+7.1f}%" if abs(score) < 1000 else f"{'unstable':>8s}"
        lines.append(f"{c['name']:26s} {sc} {t:>7s} {c['t_crit']:6.2f}  "
                     f"{candidate_verdict(c, js['found'], gone)}")
    for st in js["steps"]:
        for c in st.get("pairs", []):
            after = f" after {', '.join(st['model'])}" if st["model"] else ""
            lines.append(f"tried together{after}: {c['name']} "
                         f"({100 * (c['score'] or 0.0):+.1f}%, t {c['t'] or 0.0:.2f}): "
                         f"{'added' if added(c['name'], js['found']) else c['why']}")
    lines.append("")
    for tag in ("base", "extended"):
        e = js[tag]
        pay = e["payload"]
        rr = e["residual_rms"]
        verified = n_of(pay.get("passes", 0), "verified pass", "verified passes")
        s = (f"{tag:9s} residual hoist {rr['hoist_A']:.2f} A, crowd {rr['crowd_A']:.2f} A; "
             f"held-out payload ({verified}): ")
        if pay.get("passes"):
            s += (f"mean {pay['mean_kg']:+.0f} kg ({pay['mean_pct_rated']:+.2f} %), "
                  f"RMS {pay['rms_kg']:.0f} kg ({pay['rms_pct_rated']:.2f} % of rated)")
            if "payload_engine" in e and e["payload_engine"].get("passes"):
                s += f"; live engine RMS {e['payload_engine']['rms_kg']:.0f} kg"
        else:
            s += "none"
        lines.append(s)
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from shoveld.diagnose import diagnose
    from shoveld.diagnose.report import as_json, write_report
    from shoveld.diagnose.select import SelectionConfig

    if args.report:
        check_output(args.report, folder=True)
    refuse_repeats(args.calib)
    refuse_repeats(args.measured)
    calib = read_tables(args.calib)
    measured = read_tables(args.measured)
    cfg = SelectionConfig(alpha=args.alpha, min_gain=args.min_gain,
                          max_effects=args.max_effects)
    try:
        d = diagnose(calib, measured, parse_effects(args.candidates) or None, cfg,
                     args.method, engine=not args.no_engine)
    except ValueError as e:
        raise CliError(str(e)) from None
    js = as_json(d)
    if args.report:
        path = write_report(d, args.report)
        print(f"wrote {path}", file=sys.stderr)
    if args.json:
        print(json.dumps(js))
    else:
        print(_summary(js))
    return 0
