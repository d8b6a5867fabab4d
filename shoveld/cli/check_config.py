"""``shoveld check-config``: validate a configuration file without starting anything."""

from __future__ import annotations

import argparse

from shoveld.cli import CliError


def register(sub: argparse._SubParsersAction) -> None:
    from shoveld.paths import CONFIG_SEARCH

    p = sub.add_parser(
        "check-config", help="validate the service configuration",
        description="Reads the TOML file, checks every key (devices through their drivers' "
                    "own checks), the calibrated parameters file it names, and that every "
                    "signal the payload needs has a source; with [zenoh.tls], that the "
                    "certificates and key are readable and in date and every endpoint is "
                    "tls/. Prints a summary, or the first "
                    "problem naming the key, and exits 2.")
    p.add_argument("config", nargs="?", default=None, metavar="FILE",
                   help=f"the configuration (default: {CONFIG_SEARCH})")
    p.add_argument("--no-params", action="store_true",
                   help="do not load the parameters file (checking on another machine)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from shoveld.daemon.config import (
        ConfigError,
        check_params,
        check_tls_files,
        load_config,
    )

    try:
        from shoveld.paths import find_config

        args.config = args.config or find_config()
        cfg = load_config(args.config)
        tls_notes = check_tls_files(cfg)
        params = None if args.no_params else check_params(cfg)
    except ConfigError as e:
        raise CliError(str(e)) from None
    print(f"{args.config}: OK")
    print(f"  shovel {cfg.shovel_id}: loop {cfg.loop.rate_hz:g} Hz, state {cfg.state_dir}")
    if params is not None:
        from shoveld.payload.misfit import calibration_note

        print(f"  params {cfg.params_path}: terms {', '.join(params.terms)}")
        lacks = calibration_note(params.fit)
        if lacks:  # the file is usable, its model is short of something: said, not refused
            print(f"    warning: {lacks}")
    z = cfg.zenoh
    print(f"  zenoh {z.mode}: listen {list(z.listen)} connect {list(z.connect)}, "
          f"keys {z.prefix}/{cfg.shovel_id}/*")
    if z.tls is not None:
        acl = "with" if z.acl else "without"
        print(f"  zenoh mutual TLS, {acl} the daemon's access control")
        for n in tls_notes:
            print(f"    {n}")
    print(f"  truck target {cfg.engine.truck_target_kg:g} kg, gap {cfg.engine.truck_gap_s:g} s")
    for name, dev in cfg.devices.items():
        print(f"  device {name} ({dev.kind}, max age {dev.max_age_s:g} s): "
              f"{', '.join(dev.signals)}")
    return 0
