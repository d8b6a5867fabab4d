"""``shoveld sim``: write a signals table (and its truth) from the simulated shovel."""

from __future__ import annotations

import argparse
import json
import math
from functools import partial
from pathlib import Path

from shoveld.cli import CliError
from shoveld.cli.options import COUNT, KG, KG_OR_ZERO, SEED, number
from shoveld.words import n_of


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sim", help="simulate the shovel and write a signals table",
        description="Simulate dig cycles or a calibration trial. Writes OUT (a signals "
                    "table) and OUT.truth.json (true payload and phase times per pass).")
    p.add_argument("--scenario", choices=("cycles", "calibration"), default="cycles")
    p.add_argument("--passes", type=COUNT, default=None,
                   help="passes to dig (cycles) (default: 12)")
    p.add_argument("--load", type=KG_OR_ZERO, default=None,
                   help="known load in kg (calibration; the thesis used 8420) (default: 0)")
    p.add_argument("--payload-range", type=KG_OR_ZERO, nargs=2, metavar=("MIN", "MAX"),
                   default=None, help="draw each pass's payload from MIN..MAX kg")
    p.add_argument("--truck-target", type=KG, default=None,
                   help="truck target in kg; passes fill trucks to about it (cycles) "
                        "(default: 136000)")
    p.add_argument("--verified-fraction", type=number(0.0, 1.0), default=None,
                   help="share of passes whose scale-verified payload is written (cycles) "
                        "(default: 0)")
    p.add_argument("--rate", type=number(0.0, lo_open=True, unit="Hz"), default=50.0,
                   help="logger rate in Hz")
    p.add_argument("--seed", type=SEED, default=0, help="seed of the path and the noise")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--machine", type=SEED, default=0, metavar="N",
                   help="machine seed: draws the machine's mechanics, hoist drive and sensor "
                        "installation (offsets, gains, noise); give every file of one "
                        "machine the same N (default 0)")
    which.add_argument("--ideal", action="store_true",
                   help="the ideal machine instead: thesis values, unbiased 16-bit current "
                        "sensors, no drift, the two-level hoist field")
    p.add_argument("--noise", type=number(0.0), default=1.0, help="sensor noise multiplier")
    p.add_argument("--effect", action="append", default=[], metavar="NAME[=MAGNITUDE]",
                   help="switch on a hidden physical effect (repeatable); see --list-effects")
    p.add_argument("--list-effects", action="store_true", help="list the effects and exit")
    p.add_argument("--out", metavar="FILE",
                   help="output signals table (.csv); required (but with --list-effects)")
    p.set_defaults(func=run)


def parse_effect_args(items: list[str]) -> dict[str, float | None]:
    spec: dict[str, float | None] = {}
    for item in items:
        name, _, mag = item.partition("=")
        try:
            x = float(mag) if mag else None
        except ValueError:
            x = math.nan
        if x is not None and not math.isfinite(x):
            raise CliError(f"--effect {item!r}: magnitude must be a finite number")
        name = name.strip()
        if name in spec:
            raise CliError(f"--effect {item!r}: {name} is already switched on (by "
                           f"--effect {name}{'' if spec[name] is None else f'={spec[name]:g}'}"
                           "): give each effect once")
        spec[name] = x
    return spec


CYCLES_ONLY = ("passes", "payload_range", "truck_target", "verified_fraction")
"""Options of the dig cycles, which a calibration trial has no use for."""


def check_scenario(args: argparse.Namespace) -> None:
    """Refuse an option the scenario would not use (it was ignored: ``--load 8420`` on
    the dig cycles wrote passes of random payloads, not of 8,420 kg), then put the
    defaults in."""
    def flag(name: str) -> str:
        return "--" + name.replace("_", "-")

    if args.scenario == "cycles":
        if args.load is not None:
            raise CliError("--load is the known load of --scenario calibration; the dig "
                           "cycles draw each pass's payload (--payload-range MIN MAX sets "
                           "its range)")
        if args.payload_range and args.truck_target is not None:
            raise CliError("--truck-target fills trucks with passes drawn to suit it, and "
                           "--payload-range draws each pass in its range instead: give one")
    else:
        given = [flag(k) for k in CYCLES_ONLY if getattr(args, k) is not None]
        if given:
            raise CliError(f"{', '.join(given)}: for --scenario cycles; a calibration "
                           "trial is one run at --load KG")
    for k, v in (("passes", 12), ("load", 0.0), ("truck_target", 136000.0),
                 ("verified_fraction", 0.0)):
        if getattr(args, k) is None:
            setattr(args, k, v)


def run(args: argparse.Namespace) -> int:
    from shoveld.signals.table import write_header, write_rows, write_table
    from shoveld.sim import effects as fx
    from shoveld.sim.machine import Machine
    from shoveld.sim.scenario import iter_cycles, simulate_calibration

    if args.list_effects:
        for name, cls in sorted(fx.SIM_EFFECTS.items()):
            print(f"{name:26s} default {cls.default_magnitude:g} {cls.magnitude_unit}: "
                  f"{cls.description}")
        return 0
    if not args.out:
        raise CliError("--out FILE is required")
    check_scenario(args)
    if args.payload_range and args.payload_range[0] > args.payload_range[1]:
        raise CliError(f"--payload-range {args.payload_range[0]:g} {args.payload_range[1]:g}: "
                       "expected MIN at most MAX")
    try:
        effects = fx.make_effects(parse_effect_args(args.effect), form="bench")
    except ValueError as e:
        raise CliError(str(e)) from None
    machine = Machine.ideal() if args.ideal else Machine.draw(args.machine)
    if args.noise != 1.0:
        from dataclasses import replace

        machine = replace(machine, sensors=machine.sensors.scaled(args.noise))
    if args.scenario == "cycles":
        if args.payload_range:
            lo, hi = args.payload_range
            cycles = partial(iter_cycles, payload_range=(lo, hi), truck_target_kg=None)
        else:
            cycles = partial(iter_cycles, truck_target_kg=args.truck_target)
        # Streamed: a segment of whole trucks at a time goes to disk, so memory does not
        # grow with the number of passes (bench/sim_speed.py).
        out = Path(args.out)
        truth: dict = {}
        passes: list = []
        samples, end = 0, 0.0
        with open(out, "w", encoding="utf-8", newline="\n") as f:
            for part in cycles(args.passes, args.seed,
                               verified_fraction=args.verified_fraction,
                               rate_hz=args.rate, effects=effects, machine=machine):
                if not truth:
                    truth = part.truth
                    write_header(f, part.table.meta)
                write_rows(f, part.table)
                passes += [p.as_dict() for p in part.passes]
                samples += len(part.table)
                end = float(part.table.time[-1])
        Path(str(out) + ".truth.json").write_text(json.dumps({**truth, "passes": passes},
                                                             indent=1))
        print(f"wrote {out} ({n_of(samples, 'sample', 'samples')}, {end:.0f} s, "
              f"{n_of(len(passes), 'pass', 'passes')}) and {out}.truth.json")
        return 0
    res = simulate_calibration(args.load, args.seed, rate_hz=args.rate, effects=effects,
                               machine=machine)
    out = Path(args.out)
    write_table(out, res.table)
    Path(str(out) + ".truth.json").write_text(json.dumps(res.truth_json(), indent=1))
    print(f"wrote {out} ({n_of(len(res.table), 'sample', 'samples')}, "
          f"{res.table.time[-1]:.0f} s, {n_of(len(res.passes), 'pass', 'passes')}) and "
          f"{out}.truth.json")
    return 0
