"""``shoveld run``: the service on the shovel's computer (systemd's ExecStart)."""

from __future__ import annotations

import argparse
import logging
import signal
import threading

from shoveld.cli import CliError
from shoveld.cli.options import SECONDS

log = logging.getLogger("shoveld.run")


def register(sub: argparse._SubParsersAction) -> None:
    from shoveld.paths import CONFIG_SEARCH

    p = sub.add_parser(
        "run", help="run the payload monitor service",
        description="Starts one thread per configured device, the fixed-rate loop (engine, "
                    "payload, trucks), the pass log and Zenoh publishing. Stops cleanly on "
                    "SIGTERM/SIGINT; under systemd it sends READY and watchdog pings.")
    p.add_argument("--config", default=None, help=f"TOML file (default: {CONFIG_SEARCH})")
    p.add_argument("--state-dir", default=None,
                   help="override shovel.state_dir (where the pass log lives)")
    p.add_argument("--duration", type=SECONDS, default=None,
                   help="stop after this many seconds (tests, trials)")
    p.set_defaults(func=run)


def install_stop_signals(stop: threading.Event) -> None:
    """SIGTERM/SIGINT set ``stop``; the loop ends at its next tick."""
    def handler(signum: int, frame: object) -> None:
        log.info("signal %d: stopping", signum)
        stop.set()
    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)


def run(args: argparse.Namespace) -> int:
    from shoveld.cli.common import one_blas_thread

    one_blas_thread()  # before the daemon's imports bring numpy
    import dataclasses
    import sqlite3
    from pathlib import Path

    from shoveld.daemon.config import (
        ConfigError,
        check_params,
        check_tls_files,
        load_config,
    )
    from shoveld.daemon.logs import setup_logging
    from shoveld.daemon.service import Service

    try:
        from shoveld.paths import find_config

        args.config = args.config or find_config()
        cfg = load_config(args.config)
        if args.state_dir:
            cfg = dataclasses.replace(cfg, state_dir=Path(args.state_dir))
        params = check_params(cfg)
        check_tls_files(cfg, dates=False)
    except ConfigError as e:
        raise CliError(f"refusing to start: {e}") from None
    setup_logging("DEBUG" if args.verbose > 1 else "INFO" if args.verbose else cfg.log_level)
    try:  # an expired certificate stops Zenoh, not the weighing and the pass log
        check_tls_files(cfg)
    except ConfigError as e:
        log.error("%s: Zenoh will not connect until it is renewed", e)
    stop = threading.Event()
    install_stop_signals(stop)
    if args.duration is not None:
        threading.Timer(args.duration, stop.set).start()
    try:
        service = Service(cfg, params)
    except ValueError as e:
        raise CliError(f"refusing to start: {e}") from None
    log.info("shoveld %s starting: %d devices, loop %.0f Hz, state %s", cfg.shovel_id,
             len(cfg.devices), cfg.loop.rate_hz, cfg.state_dir)
    try:
        try:
            service.start()
        except (OSError, sqlite3.Error) as e:
            raise CliError(f"cannot open the pass log in {cfg.state_dir}: {e}") from None
        service.run(stop)
    finally:
        service.close()
    log.info("stopped")
    return 0
