"""``shoveld calibrate``: identify the model parameters from calibration trials."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import TYPE_CHECKING, Any

from shoveld.cli import CliError
from shoveld.cli.common import check_output, parse_effects, read_tables, refuse_repeats
from shoveld.cli.options import ORDER, SECONDS, number
from shoveld.identify import ANGLE_DRIFT_DEG
from shoveld.kinematics import (
    DEFAULT_POLYORDER,
    DEFAULT_WINDOW_S,
    PAYLOAD_POLYORDER,
    PAYLOAD_WINDOW_S,
)
from shoveld.words import n_of

if TYPE_CHECKING:
    from shoveld.identify.calibrate import Calibrator
    from shoveld.model.model import Model
    from shoveld.signals.table import SignalsTable


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate", help="identify model parameters from empty and known-load trials",
        description="Output-error least squares over empty and known-load trials (the "
                    "known load fixes the scale): the measured hoist and crowd currents are "
                    "the outputs, weighted by their noise; the current sensors' offsets and "
                    "the hoist's pull per ampere over the field current are identified. "
                    "Writes a params file and prints the report.")
    p.add_argument("files", nargs="+", metavar="FILE", help="signals tables")
    p.add_argument("--verified", nargs="+", default=[], metavar="TABLE",
                   help="signals tables of digging whose passes a scale verified (the "
                        "payload_kg column holds the weighed payload through each such pass): "
                        "identified together with the trials, they bring a full dipper's "
                        "currents, which the trials lack (18 simulated machines with 24 such "
                        "passes: payload RMS/CRB 1.51 -> 1.36, docs/engine.md)")
    p.add_argument("--out", required=True, help="params file to write (TOML)")
    p.add_argument("--method", choices=("output", "equation"), default="output",
                   help="output: currents as outputs, weighted by their noise (default); "
                        "equation: the thesis form, for comparison")
    p.add_argument("--effects", default="", metavar="NAME,...",
                   help="extension terms to add to the base model")
    p.add_argument("--window", type=SECONDS, default=DEFAULT_WINDOW_S,
                   help="zero-phase smoothing window of the identification's rates, s "
                        "(recorded in the params)")
    p.add_argument("--polyorder", type=ORDER, default=DEFAULT_POLYORDER,
                   help="order of the Savitzky-Golay fit over that window")
    p.add_argument("--payload-window", type=SECONDS, default=PAYLOAD_WINDOW_S, metavar="S",
                   help="the payload equations' smoothing window, s, recorded in the params "
                        "for the engine (lift and swing are slower than the trials' strokes; "
                        "docs/engine.md, \"The payload's own smoothing\")")
    p.add_argument("--payload-polyorder", type=ORDER, default=PAYLOAD_POLYORDER, metavar="N",
                   help="order of the payload equations' Savitzky-Golay fit")
    p.add_argument("--angle-drift", type=number(0.0, unit="deg"), default=ANGLE_DRIFT_DEG,
                   metavar="DEG",
                   help="slow drift of the handle-angle sensor within a file (1 sigma, "
                        "from its data sheet), counted in the standard errors; 0: not")
    p.add_argument("--angle-noise", action=argparse.BooleanOptionalAction, default=True,
                   help="correct the fit for the handle angle's and the crowd extension's "
                        "noise (errors in variables; default). --no-angle-noise: the fit as "
                        "before 2026-11-26, whose K_C leant +0.51 standard errors over 120 "
                        "simulated machines (docs/engine.md)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--plot", metavar="DIR",
                   help="write PNG plots of the fit (residuals, exclusions) per file")
    p.set_defaults(func=run)


def format_report(params: object) -> str:
    from shoveld.model.params import ModelParams

    assert isinstance(params, ModelParams)
    units = params.model().param_units
    fit = params.fit
    lines = [f"model terms: {', '.join(params.terms)}",
             f"method: {fit['method']}, samples used: {fit['samples']}, "
             f"condition number: {fit['condition_number']:.1f}", "",
             f"{'parameter':10s} {'value':>14s} {'std err':>12s} {'rel':>7s}  unit"]
    for n, v, se, u in zip(params.names, params.values, params.stderr, units, strict=True):
        rel = abs(se / v) * 100 if v else math.inf
        lines.append(f"{n:10s} {v:14.6g} {se:12.4g} {rel:6.2f}%  {u}")
    lines.append("")
    knots = params.hyper.get("hoist_drive", {})
    if knots.get("field_knots_a"):
        lines.append(f"hoist pull per ampere over the field: knots at "
                     f"{', '.join(f'{k:g}' for k in sorted(knots['field_knots_a']))} A, "
                     f"nominal {knots['field_nominal_a']:g} A (K_H)")
    if "passes_to_trials_rms" in fit:
        lines.append("residual RMS of the verified passes over the trials': " + ", ".join(
            f"{k} {v:.2f}x" for k, v in fit["passes_to_trials_rms"].items()))
    if "current_residual_rms_a" in fit:
        lines.append("residual current RMS: " + ", ".join(
            f"{k} {v:.3g} A" for k, v in fit["current_residual_rms_a"].items()))
        for ch, cn in params.current_noise.items():
            lines.append(f"  noise model {ch}: {cn['floor_a']:.3g} A + {100 * cn['rel']:.2g} % "
                         f"of the reading, correlation time {cn['tau']:.1f} samples")
        lines.append(f"standard errors: {fit['covariance']}")
    lines.append("residual RMS: " + ", ".join(
        f"{k} {v:.4g} {'N m' if k == 'handle' else 'N'}" for k, v in fit["residual_rms"].items()))
    for name, st in fit.get("stages", {}).items():
        lines.append(f"  stage {name}: {n_of(st['samples'], 'sample', 'samples')}, condition "
                     f"{st['condition_number']:.1f}, residual " + ", ".join(
                         f"{k} {v:.4g}" for k, v in st["residual_rms"].items()))
    lines.append("")
    lines.append("data used and excluded (samples):")
    for f, ex in fit["excluded"].items():
        lines.append(f"  {f}: used {ex['used']} (static {ex['static']})")
        for why, n in ex.items():
            if why not in ("used", "static"):
                lines.append(f"    excluded {n:7d}: {why}")
    return "\n".join(lines)


def _settings(args: argparse.Namespace) -> dict[str, Any]:
    """``Calibrator``'s settings from the command line (one place for both paths)."""
    return {"method": args.method, "window_s": args.window, "polyorder": args.polyorder,
            "payload_window_s": args.payload_window,
            "payload_polyorder": args.payload_polyorder,
            "angle_drift_deg": args.angle_drift, "position_noise": args.angle_noise}


def _refuse_unexcited(model: Model, tables: list[SignalsTable],
                      args: argparse.Namespace) -> None:
    """A term the trials cannot identify is refused without ``--verified``: fitted on the
    trials alone it weighed the passes of a swinging machine 8 t heavy (its radius and
    inertia whatever the fit left them), where the diagnosis, which adds the verified
    passes, cut the error to 48 kg (``bench/pass_misfit.py --effects --extend``)."""
    from shoveld.diagnose.fit import unexcited_by_trials

    why = unexcited_by_trials(model, tables, args.window, args.polyorder)
    if why:
        raise CliError(f"--effects {args.effects}: the trials cannot identify "
                       f"{'; '.join(why)}; add scale-verified passes with --verified TABLE "
                       "(the passes' payload_kg column filled while they are weighed), as "
                       "the diagnosis does")


def _with_verified(model: Model, tables: list[SignalsTable], args: argparse.Namespace
                   ) -> Calibrator:
    """The trials plus the verified passes of ``--verified`` (the pass segmentation and
    the training files are the diagnosis's, which identifies its terms the same way)."""
    from shoveld.diagnose.fit import calibrate_with_verified

    try:
        cal, used, found = calibrate_with_verified(
            model, tables, read_tables(args.verified), **_settings(args))
    except ValueError as e:
        raise CliError(f"--verified {' '.join(args.verified)}: {e}") from None
    print(f"identified with {n_of(used, 'verified pass', 'verified passes')} of {found} in "
          f"{n_of(len(args.verified), 'table', 'tables')}", file=sys.stderr)
    _warn_passes_to_trials(cal)
    return cal


def _warn_passes_to_trials(cal: Calibrator) -> None:
    """One line on stderr when the verified passes' residuals are well above the trials':
    the model lacks something operation excites, and the daemon's misfit, read against
    this calibration's noise, will not see it (``PASSES_TO_TRIALS_WARN``). The ratio is
    recorded with the params, so ``check-config`` and the daemon's health say it too."""
    from shoveld.payload.misfit import calibration_note

    note = calibration_note(cal.params_.fit if cal.params_ else {})
    if note:
        print(f"warning: {note}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    from shoveld.identify.calibrate import Calibrator
    from shoveld.model.model import Model
    from shoveld.model.params import save_params

    check_output(args.out)
    if args.plot:
        check_output(args.plot, folder=True)
    refuse_repeats(args.files + args.verified)
    tables = read_tables(args.files)
    try:
        model = Model.from_names(parse_effects(args.effects))
        if args.verified:
            cal = _with_verified(model, tables, args)
        else:
            _refuse_unexcited(model, tables, args)
            cal = Calibrator(model=model, **_settings(args)).fit(tables)
    except ValueError as e:
        raise CliError(str(e)) from None
    assert cal.params_ is not None
    save_params(args.out, cal.params_)
    if args.plot:
        from shoveld.plots import plot_calibration

        try:
            for path in plot_calibration(cal, args.plot):
                print(f"plot: {path}", file=sys.stderr)
        except RuntimeError as e:
            raise CliError(str(e)) from None
    if args.json:
        print(json.dumps({"params": cal.params_.as_dict(),
                          "stderr": dict(zip(cal.params_.names,
                                             map(float, cal.params_.stderr), strict=True)),
                          **cal.params_.fit}))
    else:
        print(format_report(cal.params_))
        print(f"\nwrote {args.out}")
    return 0
