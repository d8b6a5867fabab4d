"""``shoveld replay``: the whole daemon fed from a capture, publishing on Zenoh like live."""

from __future__ import annotations

import argparse
import gc
import json
import logging
import sys
import tempfile
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from shoveld.cli import CliError
from shoveld.cli.options import SECONDS, SECONDS_OR_ZERO, SHOVEL_ID, number
from shoveld.endpoints import endpoint_arg
from shoveld.payload.misfit import misfit_note

if TYPE_CHECKING:
    from shoveld.daemon.config import DaemonConfig
    from shoveld.model.params import ModelParams

log = logging.getLogger("shoveld.replay")


_PACE = number(0.0, lo_open=True, unit="times the recorded pace, e.g. 1 or 20",
               hint="--fast replays as fast as the machine allows")
"""--speed: a finite number of times the recorded pace, above zero."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay", help="run the daemon on a capture (drivers, engine, pass log, Zenoh)",
        description="Feeds a capture folder through the drivers into the daemon. --speed X "
                    "plays it on the drivers' virtual hardware (ptys, virtual CAN, a local "
                    "Modbus server) with one thread per driver, X times the recorded pace, "
                    "exactly like live. --fast runs the same drivers on in-memory transports, each "
                    "device ahead of the loop, and builds the samples in bulk: deterministic "
                    "(same passes every run) and as fast as the machine allows. Passes and "
                    "trucks are printed as they are committed.")
    p.add_argument("capture", metavar="CAPTURE", help="capture folder (manifest.json)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--speed", type=_PACE, default=None,
                      help="times the recorded pace, > 0 (default 1.0)")
    mode.add_argument("--fast", action="store_true", help="as fast as possible, deterministic")
    p.add_argument("--config", default=None,
                   help="daemon config for params, loop, engine, truck and Zenoh settings "
                        "(its devices are ignored: the capture's are used; a wrong key in them is "
                        "still named)")
    p.add_argument("--params", default=None,
                   help="params file (overrides the config's; default: the capture folder's "
                        "params.toml when neither this nor --config is given)")
    p.add_argument("--state-dir", default=None,
                   help="pass log directory (default: a temporary one, removed at the end)")
    p.add_argument("--id", type=SHOVEL_ID, default=None,
                   help="shovel id on Zenoh (default: the config's, else 'replay')")
    p.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                   type=endpoint_arg,
                   help="Zenoh listen endpoint (repeatable; default tcp/127.0.0.1:7447)")
    p.add_argument("--connect", action="append", default=None, metavar="ENDPOINT",
                   type=endpoint_arg, help="Zenoh endpoint to connect to (repeatable)")
    p.add_argument("--mode", choices=("peer", "client"), default=None)
    p.add_argument("--zenoh-wait", type=SECONDS_OR_ZERO, default=2.0,
                   help="seconds to wait for the Zenoh session before playing")
    p.add_argument("--until", type=SECONDS, default=None, metavar="S",
                   help="stop at this capture time (seconds from its start)")
    p.add_argument("--wait-subscribers", type=SECONDS_OR_ZERO, default=0.0, metavar="S",
                   help="wait up to S seconds for a subscriber of the pass topic before "
                        "playing (so it sees every pass)")
    p.add_argument("--keep-open", type=SECONDS_OR_ZERO, default=0.0, metavar="S",
                   help="stay on Zenoh this long after the end (late subscribers, queries)")
    p.add_argument("--json", action="store_true", help="JSON lines on stdout")
    # everything it opens is closed and removed before run returns (see run)
    p.set_defaults(func=run, exit_at_once=True)


def build_config(args: argparse.Namespace, state_dir: Path) -> tuple[DaemonConfig, ModelParams]:
    """The daemon config and params for a replay, from --config and the overrides."""
    import dataclasses

    from shoveld.cli.common import read_params
    from shoveld.daemon.config import ConfigError, check_params, load_config, parse_config

    cap = Path(args.capture)
    if not cap.is_dir():
        raise CliError(f"{args.capture}: " + ("not a folder" if cap.exists() else "no such folder")
                       + ": expected a capture folder (its manifest.json and recordings)")
    try:
        if args.config:
            # its devices are checked key by key (a config with a wrong one is wrong
            # wherever it is used), not for covering the payload: the capture's are used
            cfg = load_config(args.config, require_devices=False)
        else:
            if not args.params:
                own = Path(args.capture) / "params.toml"
                if not own.is_file():
                    raise CliError(f"{args.capture}: no params.toml in the capture; give "
                                   "--params FILE (or --config FILE naming one)")
                args.params = str(own)
            cfg = parse_config({"shovel": {"id": "replay", "params": str(args.params)}},
                               "<replay>", require_devices=False)
    except ConfigError as e:
        raise CliError(str(e)) from None
    z = cfg.zenoh
    zr = dataclasses.replace(
        z, mode=args.mode or z.mode,
        listen=tuple(args.listen) if args.listen is not None else z.listen,
        connect=tuple(args.connect) if args.connect is not None else z.connect)
    cfg = dataclasses.replace(cfg, zenoh=zr, state_dir=state_dir,
                              shovel_id=args.id or cfg.shovel_id)
    if args.params:
        params = read_params(args.params)
    else:
        try:
            params = check_params(cfg)
        except ConfigError as e:
            raise CliError(str(e)) from None
    return cfg, params


def run(args: argparse.Namespace) -> int:
    from shoveld.cli.common import one_blas_thread

    one_blas_thread()  # before the daemon's imports bring numpy
    # No cyclic collection while the daemon's modules load (numpy, the engine, the
    # drivers): what they make lives to the end, and the collector's passes over it
    # were 5-10 ms of the command.
    collecting = gc.isenabled()
    gc.disable()
    try:
        import sqlite3

        from drivers.capture.format import CaptureFormatError
        from shoveld.daemon.logs import setup_logging
        from shoveld.payload.trucks import truck_line
        from shoveld.replay.service import fast_replay_service, replay_service
    finally:
        if collecting:
            gc.enable()

    setup_logging("DEBUG" if args.verbose > 1 else "INFO" if args.verbose else "WARNING")
    tmp = None
    if args.state_dir:
        state_dir = Path(args.state_dir)
    else:
        tmp = tempfile.TemporaryDirectory(prefix="shoveld-replay-")
        state_dir = Path(tmp.name)
    try:
        cfg, params = build_config(args, state_dir)
        try:
            if args.fast:
                rr = fast_replay_service(args.capture, cfg, params)
            else:
                rr = replay_service(args.capture, cfg, params,
                                    args.speed if args.speed is not None else 1.0)
        except (CaptureFormatError, FileNotFoundError) as e:
            raise CliError(str(e)) from None

        def on_event(kind: str, msg: dict[str, object]) -> None:
            if args.json:
                print(json.dumps({"topic": kind, **msg}), flush=True)
            elif kind == "pass":
                val = (f"{msg['payload_kg']:9.0f} kg +- {msg['std_kg']:5.0f} kg"
                       if msg["valid"] else f"INVALID: {msg['reason']}")
                m = msg.get("misfit")
                note = misfit_note(m if isinstance(m, float) else None, cfg.engine.misfit_warn)
                print(f"pass {msg['pass']:4d}  truck {msg['truck']:3d}  {val}{note}", flush=True)
            elif msg.get("closed"):
                print(f"truck {msg['truck']:3d} closed: {truck_line(msg)}", flush=True)

        rr.service.on_event = on_event
        # a temporary pass log is removed below: syncing it to disk protects nothing
        rr.service.durable_pass_log = tmp is None
        stop = threading.Event()
        from shoveld.cli.run import install_stop_signals

        install_stop_signals(stop)
        try:
            try:
                rr.service.start(zenoh_wait_s=args.zenoh_wait)
            except (OSError, sqlite3.Error) as e:
                raise CliError(f"cannot open the pass log in {cfg.state_dir}: {e}") from None
            if args.wait_subscribers > 0 and not rr.service.publisher.wait_subscribers(
                    args.wait_subscribers):
                log.warning("no subscriber after %.1f s; playing anyway", args.wait_subscribers)
            figures = rr.run(stop, until_s=args.until)
            rr.service.flush()
            if args.keep_open > 0:
                stop.wait(args.keep_open)
        finally:
            rr.close()
        if args.json:
            print(json.dumps({"topic": "replay", **figures}))
        else:
            print(f"replayed {figures['capture_s']:.1f} s of capture in {figures['real_s']:.1f} s"
                  f" ({figures['speed_x']}x real time, {figures['cpu_s']:.1f} s CPU)",
                  file=sys.stderr)
    finally:
        if tmp is not None:
            tmp.cleanup()
    return 0
