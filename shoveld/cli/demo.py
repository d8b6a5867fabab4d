"""``shoveld demo`` (``./run-demo``): simulated shovel, virtual hardware, daemon, cab view.

Out of the box on loopback: calibrates the simulated shovel (two simulated trials,
a few seconds) into a temporary state directory, simulates some dig cycles, plays
them as device byte streams through the emulators (MTi on a pty, AR4000 on a pty,
two Modbus TCP modules on 127.0.0.1), and runs the service exactly as ``shoveld
run`` does - drivers, fixed-rate loop, engine, pass log, Zenoh peer listening on
``tcp/127.0.0.1:7447`` - while the cab view, a separate Zenoh session, shows the
live payload, the passes and the truck. It ends by itself when the simulated
shift is over.
"""

from __future__ import annotations

import argparse
import logging
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from shoveld.cli import CliError
from shoveld.cli.options import COUNT, KG, SEED, number
from shoveld.words import n_of

log = logging.getLogger("shoveld.demo")

TEMPLATE = Path(__file__).resolve().parents[2] / "examples" / "demo.toml"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo", help="simulated shovel + virtual hardware + daemon + cab view, on loopback",
        description="Runs the whole chain on this machine: the simulated shovel's devices "
                    "as emulators, the daemon reading them through the real drivers, Zenoh on "
                    "loopback, and the cab view in this terminal. About two minutes by "
                    "default; --passes for longer.")
    p.add_argument("--passes", type=COUNT, default=4, help="dig cycles to simulate (default 4, "
                   "about 25 s each)")
    p.add_argument("--speed", type=number(0.0, lo_open=True, unit="times real time"), default=1.0,
                   help="times real time (the daemon runs on the same simulated clock)")
    p.add_argument("--seed", type=SEED, default=7)
    p.add_argument("--truck-target", type=KG, default=136000.0)
    p.add_argument("--port", type=number(1, 65535, integer=True), default=7447,
                   help="Zenoh listen port on 127.0.0.1")
    p.add_argument("--params", default=None,
                   help="use this params file instead of calibrating first")
    p.add_argument("--state-dir", default=None,
                   help="keep the pass log here (default: a temporary directory)")
    p.add_argument("--lines", action="store_true",
                   help="print one line per event even on a terminal")
    p.add_argument("--web", action="store_true",
                   help="the cab page is the display: print events as lines here and keep "
                        "the page up until Ctrl-C after the shift (the page is served in "
                        "every demo; its address is printed)")
    p.add_argument("--listen", default="127.0.0.1:8080", metavar="HOST:PORT",
                   help="address of the cab page (default 127.0.0.1:8080; the next free "
                        "port if taken)")
    p.set_defaults(func=run)


def _toml(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def write_demo_config(path: Path, *, params: Path, state_dir: Path, port: int,
                      truck_target: float, shovel_config: dict[str, Any]) -> Path:
    """The template with its placeholders filled and the emulators' devices appended."""
    if not TEMPLATE.exists():
        raise CliError(f"demo config template {TEMPLATE} is missing (run from a checkout)")
    text = TEMPLATE.read_text(encoding="utf-8")
    endpoint = f"tcp/127.0.0.1:{port}"
    for k, v in {"params": str(params), "state_dir": str(state_dir),
                 "listen_endpoint": endpoint, "truck_target": repr(float(truck_target))}.items():
        text = text.replace("{" + k + "}", v)
    lines = [text.rstrip(), "", "[installation]"]
    lines += [f"{k} = {_toml(v)}" for k, v in shovel_config["installation"].items()]
    for name, dev in shovel_config["devices"].items():
        lines += ["", f"[devices.{name}]"]
        lines += [f"{k} = {_toml(v)}" for k, v in dev.items()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def calibrate_demo(out: Path) -> Path:
    """Two simulated calibration trials (empty, known load) -> params file."""
    from shoveld.identify.calibrate import Calibrator
    from shoveld.model.model import Model
    from shoveld.model.params import save_params
    from shoveld.sim.scenario import simulate_calibration

    tables = [simulate_calibration(0.0, 1).table, simulate_calibration(8420.0, 2).table]
    cal = Calibrator(model=Model.from_names([])).fit(tables)
    assert cal.params_ is not None
    save_params(out, cal.params_)
    return out


def _port_free(port: int) -> bool:
    """Whether nothing listens on ``port``: bound as Zenoh binds its listener (with
    ``SO_REUSEADDR``), so the last demo's connections waiting out their TIME_WAIT do not
    read as a port in use."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def run(args: argparse.Namespace) -> int:
    import dataclasses
    import sqlite3

    from drivers.capture.clock import ReplayClock
    from hil_fixtures.virtual_shovel import VirtualShovel
    from shoveld.cli.cab import CabClient, CabState, show
    from shoveld.daemon.clock import ReplayPacedClock
    from shoveld.daemon.config import ConfigError, check_params, load_config
    from shoveld.daemon.logs import setup_logging
    from shoveld.daemon.service import Service
    from shoveld.sim.scenario import simulate_cycles

    if not _port_free(args.port):
        raise CliError(f"127.0.0.1:{args.port} is in use (another demo or daemon?); "
                       "use --port")
    # the inputs named on the command line, before the calibration and the simulation (a
    # --params that is not there was named in the demo's own temporary config, a
    # --state-dir that is a file ended in a traceback at the daemon's start)
    if args.params:
        from shoveld.cli.common import read_params

        read_params(args.params)
    if args.state_dir:
        from shoveld.cli.common import check_output

        check_output(args.state_dir, folder=True)
    setup_logging("INFO" if args.verbose else "ERROR")
    out = sys.stdout
    tty = out.isatty() and not args.lines
    tmp = tempfile.TemporaryDirectory(prefix="shoveld-demo-")
    work = Path(tmp.name)
    state_dir = Path(args.state_dir) if args.state_dir else work / "state"
    try:
        t0 = time.monotonic()
        if args.params:
            params_path = Path(args.params).resolve()
        else:
            print("calibrating the simulated shovel (two simulated trials) ...", flush=True)
            params_path = calibrate_demo(work / "params.toml")
        print(f"simulating {n_of(args.passes, 'dig cycle', 'dig cycles')} ...", flush=True)
        sim = simulate_cycles(args.passes, args.seed, truck_target_kg=args.truck_target)
        table = sim.table
        duration = float(table.time[-1] - table.time[0])
        clock = ReplayClock(0.0, speed=args.speed)
        with VirtualShovel(table, clock=clock) as shovel:
            cfg_path = write_demo_config(work / "shoveld.toml", params=params_path,
                                         state_dir=state_dir, port=args.port,
                                         truck_target=args.truck_target,
                                         shovel_config=shovel.config())
            try:
                cfg = load_config(cfg_path)
                params = check_params(cfg)
            except ConfigError as e:
                raise CliError(str(e)) from None
            cfg = dataclasses.replace(cfg, log_level="error")
            origin = time.time() - clock.now()
            service = Service(cfg, params, clock=ReplayPacedClock(clock, origin),
                              driver_clock=clock, close_truck_at_end=True)
            print(f"daemon config {cfg_path}; Zenoh on tcp/127.0.0.1:{args.port} "
                  f"(also try: shoveld cab --connect tcp/127.0.0.1:{args.port})", flush=True)
            print(f"playing {duration:.0f} s of shovel time at {args.speed:g}x "
                  f"(ready in {time.monotonic() - t0:.0f} s)", flush=True)
            try:
                service.start(zenoh_wait_s=5.0)
            except (OSError, sqlite3.Error) as e:  # as run and replay say it
                service.close()
                raise CliError(f"cannot open the pass log in {cfg.state_dir}: {e}") from None
            stop = threading.Event()
            end_t = clock.now() + duration + 1.0
            loop = threading.Thread(target=service.run, args=(stop, lambda: clock.now() >= end_t),
                                    name="loop", daemon=True)
            loop.start()
            state = CabState()
            cab = CabClient(state, [f"tcp/127.0.0.1:{args.port}"], "client", cfg.shovel_id)
            page = page_client = None
            try:
                page, page_client = _start_page(args, cfg.shovel_id)
                if args.web:
                    tty = False
                cab.query_status()
                watcher = threading.Event()

                def wait_loop() -> None:
                    loop.join()
                    service.flush()
                    time.sleep(0.5)  # let the last truck message reach the cab
                    watcher.set()
                threading.Thread(target=wait_loop, daemon=True).start()
                try:
                    show(state, out, tty, watcher)
                except KeyboardInterrupt:
                    stop.set()
                    loop.join(timeout=5)
                if args.web and page is not None:
                    print(f"shift over; the cab page stays up at {page.url} until Ctrl-C",
                          flush=True)
                    try:
                        threading.Event().wait()
                    except KeyboardInterrupt:
                        pass
            finally:
                cab.close()
                if page_client is not None:
                    page_client.close()
                if page is not None:
                    page.close()
                stop.set()
                loop.join(timeout=5)
                service.close()
        _summary(state, service, out)
    finally:
        tmp.cleanup()
    return 0


def _start_page(args: argparse.Namespace, shovel: str) -> tuple[Any, Any]:
    """The cab page beside the terminal view (``shoveld.web``); its address is printed.
    A taken port moves on to a free one: the demo must not fail for a second copy."""
    from shoveld.cli.cab import TOPICS, CabClient
    from shoveld.web.server import ThreadedScreen, parse_listen
    from shoveld.web.state import ScreenState

    try:
        host, port = parse_listen(args.listen)
    except ValueError as e:
        raise CliError(str(e)) from None
    state = ScreenState()
    client = CabClient(state, [f"tcp/127.0.0.1:{args.port}"], "client", shovel,
                       topics=TOPICS | {"joints"})
    state.set_link("up", f"tcp/127.0.0.1:{args.port}")
    try:
        page = ThreadedScreen(state, host, port)
    except OSError:
        page = ThreadedScreen(state, host, 0)
    client.query_status()
    print(f"cab page: {page.url}  (open it in a browser)", flush=True)
    return page, client


def _summary(state: Any, service: Any, out: Any) -> None:
    from shoveld.payload.trucks import truck_line

    if not out.isatty():
        pass
    lines = ["", "demo finished."]
    for v in state.shovels.values():
        for c in v.closed:
            lines.append(f"  truck {c['truck']}: {truck_line(c)}")
    st = service.loop_stats.as_dict(service.cfg.loop.rate_hz)
    j = st.get("jitter_ms") or {}
    lines.append(f"  loop: {n_of(st['ticks'], 'tick', 'ticks')}, "
                 f"{n_of(st['overruns'], 'overrun', 'overruns')}, jitter p50 "
                 f"{j.get('p50')} ms p99 {j.get('p99')} ms; passes written "
                 f"{service.passes_written}")
    out.write("\n".join(lines) + "\n")
    out.flush()
