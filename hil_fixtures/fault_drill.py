"""Sensor and network faults made during passes on a live virtual shovel, and how soon
health names them.

Issue 12 asks that health name a sensor fault "within one health period", the loop keep
its rate, estimates made without valid inputs not be published as numbers, and no
finished pass be lost. The drill runs the whole daemon (:class:`Service`) on the
virtual shovel's emulators at real time, connected to a site router (its own process),
with a Zenoh subscriber in this process beside it as a cab would be, and makes each
fault of :data:`FAULTS` while a pass is under way (one that makes its device's inputs
invalid while the pass is weighed, in lift or swing; the other in dig, lift, swing or
dump), then clears it and waits for health to be clear again. For each it measures the
time from the fault to the arrival of the first health message naming its device, and
counts the live estimates published as numbers while the fault's inputs were invalid.
``tests/daemon/test_fault_drill.py`` holds the bound on one drill;
``bench/fault_latency.py`` prints the figures of several.
"""

from __future__ import annotations

import json
import random
import statistics
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from hil_fixtures.net import free_port
from hil_fixtures.router import Router
from hil_fixtures.virtual_shovel import VirtualShovel
from shoveld.cycle.phases import ESTIMATING, PHASES
from shoveld.signals.table import SignalsTable


def wrong_protocol(answer: bytes) -> bytes:
    """A Modbus TCP answer as a device speaking another protocol on the port sends it."""
    return answer[:2] + b"\x12\x34" + answer[4:]


@dataclass(frozen=True)
class Rig:
    """What the drill makes its faults in: the virtual shovel and the site's router."""

    shovel: VirtualShovel
    router: Router


def _set(obj: Callable[[Rig], Any], attr: str, value: Any) -> Callable[[Rig], None]:
    return lambda rig: setattr(obj(rig), attr, value)


@dataclass(frozen=True)
class Fault:
    """One fault of one device (or of the site network), made and cleared on the rig."""

    name: str
    device: str
    """The device whose entry in health's problems names it (``"mti: ..."``; the site
    network's, ``"zenoh: ..."``)."""
    make: Callable[[Rig], object]  # (what make and clear return is not used)
    clear: Callable[[Rig], object]
    invalidates: bool = True
    """While it lasts, the device's inputs are invalid (a module answering late still
    gives most of its readings)."""
    says: str = ""
    """Words the device's entry must hold to count as naming this fault (a module
    answering late is first "not answering", from its timeouts, before a late answer
    lands and health says what it is); empty: any entry of the device."""


def _mti(rig: Rig) -> Any:
    return rig.shovel.mti


def _laser(rig: Rig) -> Any:
    return rig.shovel.laser


def _adc(rig: Rig) -> Any:
    return rig.shovel.adc_motors.server


FAULTS: tuple[Fault, ...] = (
    Fault("MTi unplugged", "mti", lambda r: _mti(r).unplug(), lambda r: _mti(r).plug()),
    Fault("MTi silent", "mti", lambda r: _mti(r).go_silent(), lambda r: _mti(r).come_back()),
    Fault("laser unplugged", "laser", lambda r: _laser(r).unplug(),
          lambda r: _laser(r).plug()),
    Fault("laser silent", "laser", _set(_laser, "silent", True), _set(_laser, "silent", False)),
    Fault("laser babbling", "laser", _set(_laser, "babble", 1.0), _set(_laser, "babble", 0.0)),
    Fault("Modbus module powered off", "adc_motors", lambda r: r.shovel.adc_motors.stop(),
          lambda r: r.shovel.adc_motors.start()),
    Fault("Modbus module silent", "adc_motors", _set(_adc, "silent", True),
          _set(_adc, "silent", False)),
    Fault("Modbus module babbling", "adc_motors", _set(_adc, "garble", wrong_protocol),
          _set(_adc, "garble", None)),
    Fault("Modbus module answering late", "adc_motors", _set(_adc, "delay_s", 0.3),
          _set(_adc, "delay_s", 0.0), invalidates=False, says="answering after its timeout"),
    Fault("site router gone", "zenoh", lambda r: r.router.stop(), lambda r: r.router.start(),
          invalidates=False, says="cannot reach"),
    Fault("site router hung", "zenoh", lambda r: r.router.hang(), lambda r: r.router.resume(),
          invalidates=False, says="cannot reach"),
)


def faults_for(adc_transport: str) -> tuple[Fault, ...]:
    """:data:`FAULTS` for the modules' transport: over RTU a module answering late has
    its readings invalid while it lasts (an RTU answer does not say which request it
    answers; docs/drivers-modbus.md), so the drill counts the numbers published then."""
    if adc_transport == "tcp":
        return FAULTS
    return tuple(replace(f, invalidates=True) if f.name == "Modbus module answering late"
                 else f for f in FAULTS)


PASS_PHASES = frozenset({"dig", "lift", "swing", "dump"})
WEIGHING = frozenset(PHASES[p] for p in ESTIMATING)
"""The phases whose live estimate is being weighed (lift, swing): the engine's."""


@dataclass
class Outcome:
    """One fault of a drill."""

    fault: str
    phase: str
    """The engine's phase when it was made."""
    latency_s: float | None
    """From the fault to the first health message naming it (its device, with the
    fault's ``says``; None: not named within the drill's wait)."""
    named: list[str]
    """That message's problems about the device."""
    numbers_while_invalid: int = 0
    """Live estimates of the weighing phases (lift, swing) published with a number while
    the fault's inputs were invalid (goal 0): after health named it, and after its
    inputs' last good reading had turned stale (``max_age_s``) and the engine's lag had
    passed (an estimate is made half a smoothing window late: until then from samples
    of before), and before it was cleared. In the other phases the live estimate holds
    the pass's payload, made from the inputs of its lift and swing."""
    live_while: int = 0
    """Live estimates of the weighing phases received in that time."""


@dataclass
class Drill:
    """A drill's outcomes and the loop's figures over it."""

    outcomes: list[Outcome]
    health_period_s: float
    max_age_s: float
    ticks: int
    seconds: float
    overruns: int
    passes_published: int
    passes_logged: int
    notes: list[str] = field(default_factory=list)

    @property
    def rate_hz(self) -> float:
        return self.ticks / self.seconds if self.seconds > 0 else 0.0


class _Watch:
    """A Zenoh client session on the daemon's health and live topics, stamping each
    message with its arrival (``time.monotonic()``), as a cab receives them."""

    def __init__(self, endpoint: str, shovel: str) -> None:
        import zenoh

        from shoveld.daemon.publisher import zenoh_config

        self.session = zenoh.open(zenoh_config("client", (), [endpoint]))
        self.lock = threading.Lock()
        self.health: list[tuple[float, dict[str, Any]]] = []
        self.live: list[tuple[float, dict[str, Any]]] = []
        self.passes: list[dict[str, Any]] = []

        def on(sample: Any) -> None:
            t = time.monotonic()
            key = str(sample.key_expr)
            msg = json.loads(sample.payload.to_bytes())
            with self.lock:
                if key.endswith("/health"):
                    self.health.append((t, msg))
                elif key.endswith("/payload/live"):
                    self.live.append((t, msg))
                elif key.endswith("/pass"):
                    self.passes.append(msg)

        self.sub = self.session.declare_subscriber(f"shovel/{shovel}/**", on)

    def health_after(self, t0: float) -> list[tuple[float, dict[str, Any]]]:
        with self.lock:
            return [(t, m) for t, m in self.health if t >= t0]

    def live_between(self, t0: float, t1: float) -> list[dict[str, Any]]:
        with self.lock:
            return [m for t, m in self.live if t0 <= t <= t1]

    def close(self) -> None:
        self.sub.undeclare()
        self.session.close()


def cycles(passes: int = 8, seed: int = 11) -> SignalsTable:
    """Dig cycles enough for a drill: a fault every pass or two, each made in a pass."""
    from shoveld.sim.scenario import simulate_cycles

    return simulate_cycles(passes, seed=seed, truck_target_kg=62000.0).table


def run_drill(table: SignalsTable, params_path: Path, state_dir: Path,
              faults: tuple[Fault, ...] | None = None, health_period_s: float = 1.0,
              name_wait_s: float = 10.0, clear_wait_s: float = 20.0, seed: int = 1,
              adc_transport: str = "tcp") -> Drill:
    """Start the daemon on a virtual shovel playing ``table``, make each fault in a pass,
    and measure (see the module's docstring). ``faults``: :func:`faults_for` the
    modules' transport (``tcp``, or ``rtu`` over pseudo-terminals)."""
    from shoveld.daemon.config import parse_config
    from shoveld.daemon.persist import read_passes
    from shoveld.daemon.publisher import wait_until
    from shoveld.daemon.service import Service
    from shoveld.model.params import load_params

    outcomes: list[Outcome] = []
    notes: list[str] = []
    if faults is None:
        faults = faults_for(adc_transport)
    with VirtualShovel(table, adc_transport=adc_transport) as vs, \
            Router(f"tcp/127.0.0.1:{free_port()}") as router:
        # the ports drawn once the emulators' servers have theirs (drawn before, the OS
        # once gave one to a Modbus server). The daemon is a peer that listens for the
        # drill's watch (a cab on the shovel's own switch, which hears it whatever the
        # site network does) and connects to the site's router.
        rig = Rig(vs, router)
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        vc = vs.config()
        cfg = parse_config({"shovel": {"id": "drill", "params": str(params_path),
                                       "state_dir": str(state_dir)},
                            "loop": {"health_period_s": health_period_s},
                            "zenoh": {"listen": [endpoint], "connect": [str(router.where)]},
                            "installation": vc["installation"], "devices": vc["devices"]})
        svc = Service(cfg, load_params(params_path))
        svc.start(zenoh_wait_s=5.0)
        stop = threading.Event()
        loop = threading.Thread(target=svc.run, args=(stop,), name="drill-loop")
        watch: _Watch | None = None
        try:
            watch = w = _Watch(endpoint, "drill")
            loop.start()
            if not svc.wait_drivers(15.0):
                errors = {n: d.health.last_error for n, d in svc.drivers.items()}
                raise RuntimeError(f"drivers not up: {errors}")

            def clear_health() -> bool:
                h = svc.health_msg
                return bool(h and h.get("ok"))

            if not wait_until(clear_health, clear_wait_s, 0.005):
                raise RuntimeError(f"health not clear: {svc.health_msg}")
            t_start, ticks0 = time.monotonic(), svc.loop_stats.ticks
            overruns0 = svc.loop_stats.overruns

            lag_s = (svc.engine.lagged.half / cfg.loop.rate_hz if svc.engine is not None
                     else 0.0)

            def phase() -> str:
                e = svc.engine
                return PHASES[e.phases.phase] if e is not None else "idle"

            rng = random.Random(seed)
            for fault in faults:
                # a moment drawn within the health period, so that the fault does not
                # always come just after a health message
                time.sleep(rng.uniform(0.0, health_period_s))
                # a fault that makes inputs invalid comes while the pass is weighed, so
                # that the live estimates it could spoil are there to be checked
                phases = WEIGHING if fault.invalidates else PASS_PHASES
                def in_phases(ph: frozenset[str] = phases) -> bool:
                    return phase() in ph

                if not wait_until(in_phases, 60.0, 0.01):
                    notes.append(f"{fault.name}: not in {sorted(phases)} within 60 s; made "
                                 "anyway")
                ph = phase()
                fault.make(rig)
                t0 = time.monotonic()

                def named(t0: float = t0, f: Fault = fault) -> tuple[float, list[str]] | None:
                    for t, m in w.health_after(t0):
                        said = [p for p in m.get("problems") or []
                                if p.startswith(f.device + ":")]
                        if said and f.says in " ".join(said):
                            return t, said
                    return None

                wait_until(lambda: named() is not None, name_wait_s, 0.005)
                got = named()
                t_named = got[0] if got else None
                out = Outcome(fault.name, ph, None if got is None else got[0] - t0,
                              [] if got is None else got[1])
                if fault.invalidates and t_named is not None:
                    # the fault stays a little longer, so that live estimates come while
                    # it is named
                    time.sleep(0.5)
                    since = max(t_named, t0 + cfg.loop.max_age_s + lag_s)
                    live = [m for m in w.live_between(since, time.monotonic())
                            if m.get("phase") in WEIGHING]
                    out.live_while = len(live)
                    out.numbers_while_invalid = sum(1 for m in live
                                                    if m.get("payload_kg") is not None)
                fault.clear(rig)
                outcomes.append(out)
                if not wait_until(clear_health, clear_wait_s, 0.02):
                    notes.append(f"{fault.name}: health not clear {clear_wait_s:g} s after "
                                 f"it was cleared: {(svc.health_msg or {}).get('problems')}")
            seconds = time.monotonic() - t_start
            ticks = svc.loop_stats.ticks - ticks0
            overruns = svc.loop_stats.overruns - overruns0
        finally:
            stop.set()
            if loop.is_alive():
                loop.join(10)
            log_path = svc.passlog.path if svc.passlog is not None else None
            svc.close()
            if watch is not None:
                with watch.lock:
                    published = len(watch.passes)
                watch.close()
        passes_logged = len(read_passes(log_path)) if log_path is not None else 0
    return Drill(outcomes, health_period_s, cfg.loop.max_age_s, ticks, seconds, overruns,
                 published, passes_logged, notes)


def summary(drills: list[Drill]) -> list[str]:
    """Lines of figures over several drills: per fault, the latency's median and largest,
    in health periods, and the live numbers published while the inputs were invalid."""
    lines = []
    for i, o in enumerate(drills[0].outcomes):
        lat = [d.outcomes[i].latency_s for d in drills]
        got = [x for x in lat if x is not None]
        nums = sum(d.outcomes[i].numbers_while_invalid for d in drills)
        live = sum(d.outcomes[i].live_while for d in drills)
        phases = ",".join(sorted({d.outcomes[i].phase for d in drills}))
        if got:
            lines.append(f"{o.fault:32s} named after {statistics.median(got):5.2f} s median, "
                         f"{max(got):5.2f} s largest ({len(got)} of {len(lat)} named; "
                         f"in {phases}); lift and swing estimates published as "
                         f"numbers while its inputs were invalid: {nums} of {live}")
        else:
            lines.append(f"{o.fault:32s} never named ({len(lat)} drills)")
    return lines
