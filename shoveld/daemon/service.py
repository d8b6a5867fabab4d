"""The service: drivers -> store -> fixed-rate loop -> engine -> pass log -> Zenoh.

Threads: one per driver (``Driver.run``, reading its transport and handing
readings to the store), the loop thread (assemble, engine step, publish joints /
live payload / health, watchdog), the pass-log thread (commit each finished pass,
then publish it and its truck), and Zenoh's own. The loop thread never waits on a
device, the disk or the network: it only reads the store, puts to Zenoh with
congestion control DROP, and queues finished passes.
"""

from __future__ import annotations

import json
import logging
import math
import queue
import sys
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from drivers.base import Driver
from shoveld.daemon.assemble import Assembler
from shoveld.daemon.clock import Clock, MonotonicClock
from shoveld.daemon.config import DaemonConfig, build_driver
from shoveld.daemon.health import LatencyStats, RateMeter, driver_health, problems
from shoveld.daemon.loop import FixedRateLoop, LoopStats, PhaseLock
from shoveld.daemon.notify import Notifier
from shoveld.daemon.persist import PassLog, db_path
from shoveld.daemon.publisher import Publisher
from shoveld.daemon.store import ReadingStore
from shoveld.engine.loop import EmptyCheck, Engine, LiveEstimate, PassResult, TruckResult
from shoveld.model.params import ModelParams
from shoveld.payload.misfit import (
    PASSES_TO_TRIALS_WARN,
    misfit_high,
    passes_to_trials_above,
    passes_to_trials_note,
    round_misfit,
)
from shoveld.payload.trucks import Truck, rule_101020
from shoveld.sample import Sample

if TYPE_CHECKING:
    from shoveld.replay.bulk import BulkAssembler

log = logging.getLogger(__name__)


def _r(x: float, nd: int) -> float | None:
    return round(x, nd) if math.isfinite(x) else None


def _jr(x: float, nd: int) -> str:
    """``x`` rounded to ``nd`` decimals as JSON text (what ``dumps(_r(x, nd))`` gives)."""
    return repr(round(x, nd)) if math.isfinite(x) else "null"


_json_str = json.encoder.encode_basestring_ascii


def joints_json(wall: float, s: Sample) -> str:
    """The ``joints`` message as JSON text, written directly: the same text as
    ``dumps`` of the equivalent dict (tested), at a fraction of the cost at 100 Hz."""
    bad = s.invalid
    return (f'{{"time":{_jr(wall, 3)},'
            f'"swing_deg":{"null" if "swing_deg" in bad else _jr(s.swing_deg, 3)},'
            f'"handle_deg":{"null" if "handle_deg" in bad else _jr(s.handle_deg, 3)},'
            f'"crowd_m":{"null" if "crowd_m" in bad else _jr(s.crowd_m, 4)},'
            f'"boom_deg":{"null" if "boom_deg" in bad else _jr(s.boom_deg, 3)},'
            f'"invalid":[{",".join(_json_str(x) for x in sorted(bad))}]}}')


JOINT_SIGNALS = frozenset({"swing_deg", "handle_deg", "crowd_m", "boom_deg"})
"""Signals of the ``joints`` message: a reading of a device that provides one of them
shows first there; other readings (motor currents) first in ``payload/live``."""
MAX_PENDING_ARRIVALS = 2000


class Service:
    """One shovel's daemon. ``start()``, then ``run(stop)`` in the calling thread."""

    def __init__(self, cfg: DaemonConfig, params: ModelParams, *, clock: Clock | None = None,
                 driver_clock: Callable[[], float] | None = None,
                 drivers: dict[str, Driver] | None = None,
                 publisher: Publisher | None = None, notifier: Notifier | None = None,
                 record_stats: bool = False, close_truck_at_end: bool = False,
                 driver_threads: bool = True,
                 before_tick: Callable[[float], None] | None = None) -> None:
        self.cfg = cfg
        self.params = params
        self.calibration_above = passes_to_trials_above(params.fit.get("passes_to_trials_rms"))
        """The channels whose verified passes fit worse than the trials in the calibration
        (``calibrate --verified``): a term missing that the misfit, read against that
        calibration's noise, does not mark; health names it for as long as it is in use."""
        self.clock: Clock = clock or MonotonicClock()
        self.driver_clock = driver_clock or time.monotonic
        self.close_truck_at_end = close_truck_at_end
        self.driver_threads = driver_threads
        self.before_tick = before_tick
        """Called with the tick time before assembly (fast replay steps its drivers here)."""
        self.durable_pass_log = True
        """False: the pass log is never synced to disk, for a state directory thrown away
        at the end (``shoveld replay`` without ``--state-dir``); set before ``start``."""
        self.store = ReadingStore(cfg.devices)
        self.drivers: dict[str, Driver] = drivers if drivers is not None else {
            name: build_driver(dev, self.driver_clock) for name, dev in cfg.devices.items()}
        self.assembler: Assembler | BulkAssembler = Assembler(
            cfg.devices, cfg.installation, self.store, self._health_of)
        """The live one; in bulk replay, the replayed samples (``shoveld.replay.service``)."""
        self.publisher = publisher or Publisher(cfg.zenoh, cfg.shovel_id, self.status)
        self.publisher.status = self.status
        self.notifier = notifier or Notifier()
        self.loop_stats = LoopStats(keep_all=record_stats)
        self.latency = LatencyStats(keep_all=record_stats)
        """Arrival (store) -> publish of every reading, all devices."""
        self.latency_by_device = {n: LatencyStats(keep_all=record_stats) for n in cfg.devices}
        self._joint_devices = frozenset(n for n, d in cfg.devices.items()
                                        if JOINT_SIGNALS.intersection(d.signals))
        self.rates = RateMeter()
        self.phase_lock = self._make_phase_lock()
        self.loop = FixedRateLoop(self.clock, cfg.loop.rate_hz, self._safe_tick,
                                  self.loop_stats, self.phase_lock)
        self.aligned_drivers = self._align_polls()
        self.tick_errors = 0
        self._consecutive_errors = 0
        self.passlog: PassLog | None = None
        self.engine: Engine | None = None
        self._stop_drivers = threading.Event()
        self._threads: list[threading.Thread] = []
        self._q: queue.Queue[tuple[Any, ...] | None] = queue.Queue()
        self._persist_thread: threading.Thread | None = None
        self.persist_error: str | None = None
        self.passes_written = 0
        self.ready = False
        self._t_start_mono = time.monotonic()
        self._tick_no = 0
        self._joints_every = max(1, round(cfg.loop.rate_hz / cfg.zenoh.joints_rate_hz))
        self._live_every = max(1, round(cfg.loop.rate_hz / cfg.zenoh.live_rate_hz))
        self._next_health = -math.inf
        self._pending_arrivals: list[tuple[str, float]] = []
        self._measure_latency = not self.clock.simulated
        self._boot_stamp: Callable[[float], str | None] | None = getattr(
            self.clock, "boot_stamp", None)
        """Dumps stamped on the live clock for the truck gap after a restart (not NTP's)."""
        """Arrival -> publish needs host time; a simulated clock has none."""
        self._prev_overruns = 0
        self._prev_ticks = 0
        # snapshots for the status query (replaced whole, read from Zenoh's thread)
        self._live: tuple[LiveEstimate, int, int, str | None] | None = None
        """The newest live estimate, its pass and truck, and what put the crowd in doubt
        (:class:`~shoveld.engine.loop.CrowdDoubt`) then, if it was."""
        self._live_built: tuple[Any, dict[str, Any]] | None = None
        self.truck_msg: dict[str, Any] | None = None
        self.truck_passes: list[dict[str, Any]] = []
        self.last_pass: dict[str, Any] | None = None
        self.health_msg: dict[str, Any] | None = None
        self.on_event: Callable[[str, dict[str, Any]], None] | None = None
        """Called from the pass-log thread after a pass/truck is committed (tests, bench)."""

    def _make_phase_lock(self) -> PhaseLock | None:
        """The PLL of ``[loop] sync``: live clocks only. On a simulated clock (replay,
        tests) readings are stamped with the tick times themselves, so there is no
        arrival phase to lock to, and the tick grid must stay the capture's."""
        lc = self.cfg.loop
        if lc.sync == "none":
            return None
        if self.clock.simulated:
            log.info("loop.sync = %r not used on a simulated clock", lc.sync)
            return None
        dev = self.cfg.devices.get(lc.sync)
        if dev is None:
            log.warning("loop.sync: no device %r here; the loop runs free", lc.sync)
            return None
        name = dev.name
        store = self.store
        return PhaseLock(1.0 / lc.rate_hz, lambda: store.latest_t(name),
                         history=lambda t: store.times_after(name, t),
                         delay_s=lc.sync_delay_s, lost_after_s=dev.max_age_s)

    def _align_polls(self) -> list[str]:
        """``[loop] align_polls``: host-polled drivers time their polls by the loop's grid,
        each in its own slot (consecutive ticks) so their answers do not compete for the
        same moment. Live clocks only, like the phase lock: on a simulated clock the
        drivers' schedule must stay the capture's for replays to be deterministic."""
        if not self.cfg.loop.align_polls or self.clock.simulated:
            return []
        hint = self.loop.tick_hint  # the loop clock is the drivers' time base live
        out: list[str] = []
        for name, drv in self.drivers.items():
            if getattr(drv, "align_to_ticks", None) is not None and \
                    drv.align_to_ticks(hint, slot=len(out)):
                out.append(name)
        return out

    @property
    def live_msg(self) -> dict[str, Any] | None:
        """The newest ``payload/live`` message (built when asked, not at every tick)."""
        live = self._live
        if live is None:
            return None
        built = self._live_built
        if built is not None and built[0] is live:
            return built[1]
        ev, pass_index, truck_index, doubt = live
        valid = bool(ev.valid and math.isfinite(ev.payload_kg))
        msg = {"time": round(self.clock.wall(ev.time_s), 3),
               "payload_kg": _r(ev.payload_kg, 1) if valid else None,
               "std_kg": _r(ev.std_kg, 1) if valid else None,
               "phase": ev.phase, "valid": valid, "pass": pass_index, "truck": truck_index,
               "crowd_doubt": doubt}
        self._live_built = (live, msg)
        return msg

    def live_json(self) -> str | None:
        """:attr:`live_msg` as JSON text, written directly (the same text as ``dumps``)."""
        live = self._live
        if live is None:
            return None
        ev, pass_index, truck_index, doubt = live
        if ev.valid and math.isfinite(ev.payload_kg):
            numbers = f'"payload_kg":{_jr(ev.payload_kg, 1)},"std_kg":{_jr(ev.std_kg, 1)}'
            valid = "true"
        else:
            numbers, valid = '"payload_kg":null,"std_kg":null', "false"
        return (f'{{"time":{_jr(self.clock.wall(ev.time_s), 3)},{numbers},'
                f'"phase":{_json_str(ev.phase)},"valid":{valid},"pass":{int(pass_index)},'
                f'"truck":{int(truck_index)},'
                f'"crowd_doubt":{"null" if doubt is None else _json_str(doubt)}}}')

    # -- lifecycle ---------------------------------------------------------------------------
    def _health_of(self, name: str) -> Any:
        d = self.drivers.get(name)
        return d.health if d is not None else None

    def start(self, zenoh_wait_s: float = 0.0) -> Service:
        """Open the pass log and restore the truck, start Zenoh and the drivers."""
        sys.setswitchinterval(0.001)  # let the loop thread get the GIL promptly
        cfg = self.cfg
        self.passlog = PassLog(db_path(cfg.state_dir), cfg.shovel_id,
                               durable=self.durable_pass_log)
        r = self.passlog.restore(self.params.fingerprint())
        self.engine = Engine(self.params, cfg.engine, first_pass=r.next_pass, first_truck=r.truck,
                             truck_passes=r.truck_passes)
        # health's payload problems go on across a restart (with the same params only)
        self.engine.carry_on(r.recent_misfits, r.empty_checks)
        now = self.clock.now()
        if r.last_dump_unix is not None:
            since = getattr(self.clock, "since_boot_stamp", None)  # the live clock has it
            elapsed = since(r.last_dump_boot) if since and r.last_dump_boot else None
            if elapsed is None:  # another boot, or not live: wall time is all there is
                elapsed = self.clock.wall(now) - r.last_dump_unix
            self.engine.last_dump_t = now - max(0.0, elapsed)
        self.truck_passes = [self._pass_msg_from_engine(p) for p in r.truck_passes]
        self.truck_msg = self._truck_msg(self.engine.truck.as_dict(), False)
        log.info("pass log %s: next pass %d, truck %d with %d passes", self.passlog.path,
                 r.next_pass, r.truck, len(r.truck_passes))
        note = passes_to_trials_note(self.calibration_above)
        if note:
            log.warning("params %s: %s", cfg.params_path, note)
        self.passlog.note_calibration(note)  # for the shift report
        self._persist_thread = threading.Thread(target=self._persist_loop, name="passlog",
                                                daemon=True)
        self._persist_thread.start()
        self.publisher.start(zenoh_wait_s)
        for name, drv in self.drivers.items():
            if not self.driver_threads:
                break
            th = threading.Thread(target=drv.run, args=(self.store.sink(name),
                                                        self._stop_drivers),
                                  name=f"driver-{name}", daemon=True)
            th.start()
            self._threads.append(th)
        self._t_start_mono = time.monotonic()
        self.notifier.status("starting: waiting for drivers")
        return self

    def drivers_up(self) -> bool:
        return all(d.health.connected for d in self.drivers.values())

    def wait_drivers(self, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self.drivers_up():
                return True
            time.sleep(0.01)
        return self.drivers_up()

    def run(self, stop: threading.Event, done: Callable[[], bool] | None = None,
            max_ticks: int | None = None) -> None:
        """Run the loop until ``stop`` is set (or ``done()``); then finish the engine if asked."""
        self.loop.run(stop, done, max_ticks=max_ticks)
        if self.close_truck_at_end and self.engine is not None:
            for ev in self.engine.finish():
                self._event(ev, self.clock.now())

    def close(self) -> None:
        """Stop drivers, drain the pass log, close Zenoh. Safe to call twice."""
        self.notifier.stopping()
        self._stop_drivers.set()
        for th in self._threads:
            th.join(timeout=5)
        self._threads.clear()
        if self._persist_thread is not None:
            self._q.put(None)
            self._persist_thread.join(timeout=30)
            self._persist_thread = None
        self.publisher.close()
        if self.passlog is not None:
            self.passlog.close()
            self.passlog = None
        self.notifier.close()

    # -- the tick ----------------------------------------------------------------------------
    MAX_CONSECUTIVE_ERRORS = 50
    """After this many failing ticks in a row the watchdog is starved: systemd restarts."""

    def _safe_tick(self, t: float) -> None:
        """A tick that raises is logged and counted, not fatal: the pass log and the truck
        are safe, and a transient fault (a strange reading) must not stop the weighing.
        A persistent one stops the watchdog pings, so systemd restarts the service."""
        try:
            self._tick(t)
            self._consecutive_errors = 0
        except Exception:  # noqa: BLE001
            self.tick_errors += 1
            self._consecutive_errors += 1
            if self._consecutive_errors in (1, 10) or self.tick_errors % 1000 == 0:
                log.exception("tick at %.3f failed (%d errors so far)", t, self.tick_errors)

    def _tick(self, t: float) -> None:
        engine = self.engine
        assert engine is not None
        if self.before_tick is not None:
            self.before_tick(t)
        assembler = self.assembler
        s = assembler.sample(t)
        pending = self._pending_arrivals
        if assembler.new_arrivals and self._measure_latency:
            pending.extend(assembler.new_arrivals)
            if len(pending) > MAX_PENDING_ARRIVALS:  # nothing published for a while
                del pending[:-MAX_PENDING_ARRIVALS]
        k = self._tick_no
        self._tick_no = k + 1
        # joints first: they need only the sample, not the engine's step
        if k % self._joints_every == 0:
            if self.publisher.put_text(
                    "joints", lambda: joints_json(self.clock.wall(t), s)) and pending:
                self._published(True)
        for ev in engine.step(s):
            if ev.__class__ is LiveEstimate:  # one every tick: kept here, not in _event
                d = engine.crowd_doubt
                self._live = (ev, engine.pass_index, engine.truck.index,
                              None if d is None else d.what)
            else:
                self._event(ev, t)
        if k % self._live_every == 0 and self._live is not None:
            if self.publisher.put_text("payload/live", self.live_json) and \
                    self._pending_arrivals:
                self._published(False)
        if t >= self._next_health:
            self._next_health = t + self.cfg.loop.health_period_s
            self._publish_health(t)
        if not self.ready and (self.drivers_up() or time.monotonic() - self._t_start_mono
                               > self.cfg.loop.ready_timeout_s):
            self.ready = True
            up = self.drivers_up()
            if not up:
                log.warning("drivers not all connected after %.0f s; running degraded",
                            self.cfg.loop.ready_timeout_s)
            self.notifier.ready("running" if up else "running degraded: drivers not all up")
        notifier = self.notifier
        if notifier.watchdog_s is not None and notifier.watchdog_due() and self._healthy():
            notifier.watchdog()  # (no watchdog, as in every replay: not even the call)

    def _published(self, joints_only: bool) -> None:
        """A message went out: the readings waiting for it have had their effect."""
        pending = self._pending_arrivals
        if self.clock.simulated:
            self._pending_arrivals = []
            return
        now = time.monotonic()
        keep: list[tuple[str, float]] = []
        joint_devices = self._joint_devices
        by_device = self.latency_by_device
        for name, arrived in pending:
            if joints_only and name not in joint_devices:
                keep.append((name, arrived))
                continue
            self.latency.add(now - arrived)
            st = by_device.get(name)
            if st is not None:
                st.add(now - arrived)
        self._pending_arrivals = keep

    def _healthy(self) -> bool:
        """Watchdog pings only while the loop keeps its schedule and the pass log lives."""
        return (self.loop.behind_s < self.cfg.loop.watchdog_max_late_s
                and self._consecutive_errors < self.MAX_CONSECUTIVE_ERRORS
                and self._persist_thread is not None and self._persist_thread.is_alive())

    def _event(self, ev: Any, t: float) -> None:
        wall = self.clock.wall
        engine = self.engine
        assert engine is not None
        if isinstance(ev, LiveEstimate):
            d = engine.crowd_doubt
            self._live = (ev, engine.pass_index, engine.truck.index,
                          None if d is None else d.what)
        elif isinstance(ev, PassResult):
            stamp = self._boot_stamp
            self._q.put(("pass", ev.as_dict(), wall(ev.start_s), wall(ev.end_s),
                         stamp(ev.end_s) if stamp is not None else None))
        elif isinstance(ev, TruckResult):
            self._q.put(("truck", ev.truck.as_dict(), ev.closed, wall(t)))
            if ev.closed and engine.truck is not ev.truck:
                self._q.put(("truck", engine.truck.as_dict(), False, wall(t)))
        elif isinstance(ev, EmptyCheck):
            self._q.put(("empty", ev.as_dict(), wall(ev.end_s), engine.empty_beyond))

    # -- pass log thread -------------------------------------------------------------------------
    def _persist_loop(self) -> None:
        while True:
            item = self._q.get()
            if item is None:
                self._q.task_done()
                return
            try:
                self._persist(item)
            except Exception as e:  # noqa: BLE001 - report, keep the thread (and watchdog) alive
                self.persist_error = f"{type(e).__name__}: {e}"
                log.exception("pass log: %s", e)
            finally:
                self._q.task_done()

    def flush(self, timeout_s: float = 30.0) -> bool:
        """Wait until every queued pass/truck is committed and published: woken by the
        pass-log thread's last ``task_done`` (polling every 5 ms cost up to that much at
        the end of every replay)."""
        q = self._q
        with q.all_tasks_done:
            return q.all_tasks_done.wait_for(lambda: not q.unfinished_tasks, timeout_s)

    def _persist(self, item: tuple[Any, ...]) -> None:
        assert self.passlog is not None
        target = self.cfg.engine.truck_target_kg
        if item[0] == "pass":
            _, p, start_u, end_u, boot = item
            for attempt in range(5):
                try:
                    self.passlog.write_pass(p, start_u, end_u, target, boot)
                    break
                except Exception as e:  # noqa: BLE001 - disk full, I/O error: retry, then say so
                    self.persist_error = f"writing pass {p['pass']}: {e}"
                    log.error("pass log: %s (attempt %d)", self.persist_error, attempt + 1)
                    time.sleep(0.2 * (attempt + 1))
            else:
                return  # not durable: not published either
            self.persist_error = None
            self.passes_written += 1
            msg = self._pass_msg(p, start_u, end_u)
            self.last_pass = msg
            if self.truck_msg is None or self.truck_msg.get("truck") != p["truck"]:
                self.truck_passes = []
            self.truck_passes = [*self.truck_passes, msg]
            log.info("pass %d (truck %d): %s", p["pass"], p["truck"],
                     f"{p['payload_kg']:.0f} kg +- {p['std_kg']:.0f} kg" if p["valid"]
                     else f"INVALID ({p['reason']})")
            self.publisher.put("pass", msg)
            if self.on_event:
                self.on_event("pass", msg)
        elif item[0] == "empty":
            # a check, not a weight: one try, and a failure is said (persist_error) as any
            _, empty, end_u, beyond = item
            self.passlog.write_empty(empty, end_u, self.cfg.engine.empty_warn_kg, beyond)
        else:
            _, tdict, closed, wall_t = item
            if closed:
                self.passlog.close_truck(tdict["truck"], target, wall_t)
            msg = self._truck_msg(tdict, closed)
            if not closed:
                if self.truck_msg is None or self.truck_msg.get("truck") != tdict["truck"]:
                    self.truck_passes = []
                self.truck_msg = msg
            else:
                if self.truck_msg is not None and self.truck_msg.get("truck") == tdict["truck"]:
                    self.truck_msg = msg
                log.info("truck %d closed: %d passes, %.0f kg (%s)", tdict["truck"],
                         tdict["passes"], tdict["total_kg"], tdict["status"])
            self.publisher.put("truck", msg)
            if self.on_event:
                self.on_event("truck", msg)

    def _pass_msg(self, p: dict[str, Any], start_u: float, end_u: float) -> dict[str, Any]:
        return {**self._pass_msg_from_engine(p), "start": round(start_u, 3),
                "end": round(end_u, 3)}

    def _pass_msg_from_engine(self, p: dict[str, Any]) -> dict[str, Any]:
        """A pass as the screens get it. ``misfit_high``: the model did not fit it (above
        this daemon's ``engine.misfit_warn``), so the screens mark its weight as doubtful
        by the daemon's own level, not one of theirs."""
        misfit = p.get("misfit")
        return {"pass": p["pass"], "truck": p["truck"], "payload_kg": p["payload_kg"],
                "std_kg": p["std_kg"], "valid": bool(p["valid"]), "samples": p["samples"],
                "reason": p.get("reason", ""), "misfit": misfit,
                "misfit_high": misfit_high(misfit, self.cfg.engine.misfit_warn)}

    def _truck_msg(self, tdict: dict[str, Any], closed: bool) -> dict[str, Any]:
        msg = {k: tdict[k] for k in ("truck", "passes", "total_kg", "std_kg", "target_kg",
                                     "fill_pct", "status", "invalid_passes")}
        msg["closed"] = closed
        if self.passlog is not None:
            since = self.clock.wall(self.clock.now()) - 3600.0 * self.cfg.rule_window_h
            closed_trucks = self.passlog.closed_truck_totals(since)
            trucks = [Truck(c.truck, c.target_kg, [{"payload_kg": c.total_kg, "std_kg": 0.0}]
                            + [{"payload_kg": None, "valid": False}] * c.not_weighed)
                      for c in closed_trucks]
            msg["rule_10_10_20"] = {"window_h": self.cfg.rule_window_h, **rule_101020(trucks)}
            # The shift so far from the pass log, so that a screen started mid-shift (or
            # restarted) shows the same totals as one that watched the whole shift.
            msg["shift"] = {"window_h": self.cfg.rule_window_h, "trucks": len(closed_trucks),
                            "passes": sum(c.passes for c in closed_trucks),
                            "kg": round(sum(c.total_kg for c in closed_trucks), 1),
                            "not_weighed": sum(c.not_weighed for c in closed_trucks),
                            "misfit_high": self.passlog.closed_trucks_misfit_high(
                                since, self.cfg.engine.misfit_warn)}
        return msg

    # -- health and status -----------------------------------------------------------------------
    def _publish_health(self, t: float) -> None:
        drivers = {name: driver_health(name, self.drivers.get(name), self.assembler.state[name],
                                       self.store, self.rates, t)
                   for name in self.cfg.devices}
        loop = self.loop_stats.as_dict(self.cfg.loop.rate_hz, self.clock.simulated)
        loop["overruns_recent"] = self.loop_stats.overruns - self._prev_overruns
        loop["ticks_recent"] = self.loop_stats.ticks - self._prev_ticks
        self._prev_overruns = self.loop_stats.overruns
        self._prev_ticks = self.loop_stats.ticks
        loop["publish_latency_ms"] = self.latency.as_dict()
        loop["publish_latency_by_device_ms"] = {n: st.as_dict()
                                                for n, st in self.latency_by_device.items()}
        pll = self.phase_lock
        loop["sync"] = ({"device": self.cfg.loop.sync, **pll.as_dict()} if pll is not None
                        else {"device": self.cfg.loop.sync, "state": "off"})
        loop["tick_errors"] = self.tick_errors
        # the calibration's own check of its verified passes against its trials
        # (calibrate --verified): a model lacking a term it will not mark pass by pass
        loop["calibration"] = {
            "passes_to_trials_rms": self.params.fit.get("passes_to_trials_rms") or None,
            "warn": PASSES_TO_TRIALS_WARN, "above": self.calibration_above}
        loop["failing_now"] = self._consecutive_errors
        if self.engine is not None:
            # how often a pass's first moments out of the bank agreed with the rest of it
            # (docs/engine.md, "The settle time, tested"): many refusals say the bank still
            # holds the dipper past the phase machine's exit, for the field engineer
            e = self.engine
            loop["settle_time"] = {"seconds": e.cfg.settle_s, "kept": e.settle_kept,
                                   "refused": e.settle_refused}
            # how well the model fitted the passes since the start (docs/engine.md, "A
            # pass's misfit"): passes above the warning level, and the last pass's
            loop["misfit"] = {"warn": e.cfg.misfit_warn, "passes_above": e.misfit_high,
                              "last": round_misfit(e.last_misfit),
                              "recent": len(e.recent_misfits),
                              "recent_above": sum(e.recent_misfits)}
            # the empty dipper weighed on the returns (docs/engine.md, "The empty dipper
            # on its returns"): the median of the last few, and how often it was beyond
            checks = e.empty_checks
            loop["empty_dipper"] = {
                "warn_kg": e.cfg.empty_warn_kg, "returns": len(checks),
                "last_kg": round(checks[-1], 1) if checks else None,
                "median_kg": round(e.empty_median, 1) if checks else None,
                "of_last": e.cfg.empty_returns, "beyond": e.empty_beyond,
                "checks_beyond": e.empty_warned}
            # the crowd in doubt since its laser lost the handle (docs/engine.md, "A crowd
            # in doubt"): the passes in a row not weighed for it, and what the laser did
            d = e.crowd_doubt
            loop["crowd_doubt"] = {
                "doubt": d.what if d else None, "usual": round_misfit(d.usual if d else None),
                "limit": round_misfit(d.limit if d else None), "refusing": e.doubt_refusing,
                "last": round_misfit(e.doubt_last_misfit), "passes_refused": e.doubt_refused}
        zen = self.publisher.health()
        persist = {"passes_written": self.passes_written, "queue": self._q.qsize(),
                   "last_error": self.persist_error}
        msg = {"time": round(self.clock.wall(t), 3), "ready": self.ready,
               "drivers": drivers, "loop": loop, "zenoh": zen, "pass_log": persist,
               "watchdog": {"enabled": self.notifier.watchdog_s is not None,
                            "pings": self.notifier.pings}}
        msg["problems"] = problems(drivers, loop, zen, persist)
        msg["ok"] = not msg["problems"]
        self.health_msg = msg
        self.publisher.put("health", msg)

    def status(self) -> dict[str, Any]:
        """The answer to ``<prefix>/<id>/status``: everything a display needs to start."""
        h = self.health_msg or {}
        return {"shovel": self.cfg.shovel_id, "time": round(self.clock.wall(self.clock.now()), 3),
                "ready": self.ready, "live": self.live_msg, "truck": self.truck_msg,
                "truck_passes": self.truck_passes, "last_pass": self.last_pass,
                "ok": h.get("ok"), "problems": h.get("problems"), "health": h or None}
