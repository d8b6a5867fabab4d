"""Modbus analog-input module driver (Modbus TCP or Modbus RTU over RS-485).

Polls the module's registers at a fixed rate through pymodbus' synchronous client
and emits one :class:`~drivers.base.Reading` per poll with the channels' values
in engineering units (the signals-table column names: ``hoist1_a``,
``boom_deg``, ...). A channel whose block timed out or was answered with a Modbus
exception is listed in ``Reading.invalid`` and *not* in ``values``: the previous
good value is never repeated as if it were new, and nothing becomes zero.

Per-channel health lives in ``health.extra["channels"][name]``: ``state``
(``ok`` / ``timeout`` / ``exception`` / ``late`` / ``never``), ``timeouts``,
``exceptions``, ``last_ok_t`` and ``stale`` (no good value for ``stale_after_s``). Over
RTU, while the module answers after its timeout (``answering_late``), its channels are
``late`` and invalid: an RTU answer does not say which request it answers.
After ``reconnect_after`` consecutive polls the module did not answer at all, ``read``
raises :class:`~drivers.base.DeviceError` and the base class reconnects with
back-off.

With a tick hint (:meth:`ModbusAdcDriver.align_to_ticks`, set by the daemon from its
loop), each poll is started its measured round trip *before* a tick of the consumer's
grid, so the answer lands just before that tick instead of anywhere up to a tick period
earlier; health ``align`` shows the lead in use and how many answers still came after
their tick. Without a hint the polls keep their own free-running schedule.

Every read can be logged (``register_log``) as a
:class:`~drivers.capture.format.RegisterRead`; ``shoveld record`` uses it.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from drivers.base import DeviceError, Driver, Reading, Sink, TickHint, check_keys
from drivers.capture.clock import clock_wait_until
from drivers.capture.format import RegisterRead
from drivers.modbus_adc.channels import Channel, ChannelMap

log = logging.getLogger(__name__)


class _SaidByTheDriver(logging.Filter):
    """pymodbus's client logs at ERROR, each with a dump of its last twenty frames, what
    the driver says itself: every unanswered request (the driver counts timeouts per
    channel in its health), and every failed connection, TCP or serial (the driver's
    "cannot connect to Modbus module at ...", once per back-off). Those lines are noise
    in the journal here, and so is the "Repeating...." pymodbus writes in their place
    when one comes again (with its dump of the frames since, when there were any: such
    lines went to the journal until 2026-12-02)."""

    SAID = ("No response received", "Connection to (")
    dropped = False

    def filter(self, record: logging.LogRecord) -> bool:
        text = str(record.getMessage())
        if text.partition("\n")[0] == "Repeating....":
            return not self.dropped
        # pyserial's "[Errno 2] could not open port /dev/ttyUSB0: ..." as it is
        self.dropped = text.startswith(self.SAID) or "could not open port" in text
        return not self.dropped


logging.getLogger("pymodbus.logging").addFilter(_SaidByTheDriver())

_FUNCTIONS = {"input": 4, "holding": 3}
FAULT_HOLD_S = 5.0
"""A Modbus module's ``babbling`` or ``answering_late`` is cleared this long after its
last sign (an answer in Modbus, in time, since)."""
_COMMON_KEYS = {"kind", "name", "unit", "function", "poll_hz", "timeout_s", "retries",
                "stale_after_s", "reconnect_after", "max_gap", "channels"}
_TCP_KEYS = {"host", "port"}
_RTU_KEYS = {"port", "baudrate", "parity", "stopbits", "bytesize"}


@dataclass(frozen=True)
class ModbusAdcConfig:
    """Configuration of one analog-input module (keys of ``[devices.<name>]``)."""

    transport: str
    """``tcp`` (kind ``modbus_tcp``) or ``rtu`` (kind ``modbus_rtu``)."""
    channels: ChannelMap
    host: str = ""
    """TCP: module address."""
    port: int | str = 502
    """TCP: port number (502). RTU: serial device path or pyserial URL."""
    unit: int = 1
    """Modbus unit / slave id."""
    function: str = "input"
    """``input`` (function 4, input registers) or ``holding`` (function 3)."""
    poll_hz: float = 50.0
    timeout_s: float = 0.1
    retries: int = 0
    stale_after_s: float = 0.5
    reconnect_after: int = 10
    max_gap: int = 8
    baudrate: int = 19200
    parity: str = "N"
    stopbits: int = 1
    bytesize: int = 8

    @property
    def function_code(self) -> int:
        return _FUNCTIONS[self.function]

    @property
    def kind(self) -> str:
        return "modbus_tcp" if self.transport == "tcp" else "modbus_rtu"

    @property
    def endpoint(self) -> str:
        return f"{self.host}:{self.port}" if self.transport == "tcp" else str(self.port)

    @classmethod
    def from_config(cls, d: Mapping[str, Any], kind: str | None = None) -> ModbusAdcConfig:
        """Build from a config table; ``ValueError`` names the offending key."""
        kind = kind or d.get("kind")
        if kind not in ("modbus_tcp", "modbus_rtu"):
            raise ValueError(f"modbus: key 'kind' must be 'modbus_tcp' or 'modbus_rtu', "
                             f"got {kind!r}")
        tcp = kind == "modbus_tcp"
        allowed = _COMMON_KEYS | (_TCP_KEYS if tcp else _RTU_KEYS)
        check_keys(kind, d, allowed, {"channels": "list of channel tables"})
        chans = ChannelMap.from_config(d["channels"], prefix=f"{kind}: channels")
        kw: dict[str, Any] = {"transport": "tcp" if tcp else "rtu", "channels": chans}

        def get(key: str, typ: type | tuple[type, ...], default: Any = None) -> Any:
            if key not in d:
                return default
            v = d[key]
            if isinstance(v, bool) or not isinstance(v, typ):
                raise ValueError(f"{kind}: key {key!r} has the wrong type ({v!r})")
            return v

        if tcp:
            host = get("host", str)
            if not host:
                raise ValueError(f"{kind}: key 'host' is required (module IP address)")
            kw["host"] = host
            kw["port"] = get("port", int, 502)
            if not 1 <= kw["port"] <= 65535:
                raise ValueError(f"{kind}: key 'port' must be in 1..65535")
        else:
            port = get("port", str)
            if not port:
                raise ValueError(f"{kind}: key 'port' is required (serial device path)")
            kw["port"] = port
            kw["baudrate"] = get("baudrate", int, 19200)
            kw["parity"] = get("parity", str, "N")
            kw["stopbits"] = get("stopbits", int, 1)
            kw["bytesize"] = get("bytesize", int, 8)
        kw["unit"] = get("unit", int, 1)
        kw["function"] = get("function", str, "input")
        kw["poll_hz"] = float(get("poll_hz", (int, float), 50.0))
        kw["timeout_s"] = float(get("timeout_s", (int, float), 0.1))
        kw["retries"] = get("retries", int, 0)
        kw["stale_after_s"] = float(get("stale_after_s", (int, float), 0.5))
        kw["reconnect_after"] = get("reconnect_after", int, 10)
        kw["max_gap"] = get("max_gap", int, 8)
        cfg = cls(**kw)
        cfg.validate(kind)
        return cfg

    def validate(self, kind: str = "modbus") -> None:
        def bad(key: str, why: str) -> ValueError:
            return ValueError(f"{kind}: key {key!r} {why} (got {getattr(self, key)!r})")

        if not 0 <= self.unit <= 247:
            raise bad("unit", "must be in 0..247")
        if self.function not in _FUNCTIONS:
            raise bad("function", "must be 'input' (fc 4) or 'holding' (fc 3)")
        if not 0 < self.poll_hz <= 1000:
            raise bad("poll_hz", "must be in (0, 1000]")
        if not 0 < self.timeout_s <= 10:
            raise bad("timeout_s", "must be in (0, 10] seconds")
        if not 0 <= self.retries <= 10:
            raise bad("retries", "must be in 0..10")
        if not self.stale_after_s > 0:
            raise bad("stale_after_s", "must be > 0")
        if self.reconnect_after < 1:
            raise bad("reconnect_after", "must be >= 1")
        if not 0 <= self.max_gap <= 124:
            raise bad("max_gap", "must be in 0..124")
        if self.transport == "rtu":
            if self.parity not in ("N", "E", "O"):
                raise bad("parity", "must be 'N', 'E' or 'O'")
            if self.stopbits not in (1, 2):
                raise bad("stopbits", "must be 1 or 2")
            if self.bytesize not in (7, 8):
                raise bad("bytesize", "must be 7 or 8")
            if self.baudrate <= 0:
                raise bad("baudrate", "must be > 0")

    def to_config(self) -> dict[str, Any]:
        """The config table this was built from (for capture manifests)."""
        d: dict[str, Any] = {"kind": self.kind, "unit": self.unit, "function": self.function,
                             "poll_hz": self.poll_hz, "timeout_s": self.timeout_s,
                             "retries": self.retries, "stale_after_s": self.stale_after_s,
                             "reconnect_after": self.reconnect_after, "max_gap": self.max_gap,
                             "port": self.port, "channels": self.channels.to_config()}
        if self.transport == "tcp":
            d["host"] = self.host
        else:
            d.update(baudrate=self.baudrate, parity=self.parity, stopbits=self.stopbits,
                     bytesize=self.bytesize)
        return d


_NONE: frozenset[str] = frozenset()


def _new_channel_health() -> dict[str, Any]:
    return {"state": "never", "timeouts": 0, "exceptions": 0, "last_ok_t": None,
            "stale": True, "last_error": None}


class PollAligner:
    """When to start polls so that their answers land just before the consumer's ticks.

    The lead (how long before its tick a poll starts) is a high percentile of the recent
    round trips (p99.5 of the last 1000, 20 s at 50 Hz, updated every 100), measured
    from the *planned* start (so a late wake-up of the thread counts), plus a margin,
    at most ``max_lead_frac`` of a tick period. An answer after its tick waits a whole
    period, one that comes early only the lead, so the lead errs on the early side; the
    cap bounds that wait, and a host stall that makes a few polls slow cannot push the
    polls far ahead of their ticks. Polls that timed out are not round
    trips and are left out. Plain arithmetic on the times it is given (no clock, no
    threads), so it is tested on simulated times.
    """

    def __init__(self, window: int = 1000, pct: float = 99.5, margin_s: float = 0.0005,
                 initial_lead_s: float = 0.002, max_lead_frac: float = 0.5,
                 update_every: int = 100) -> None:
        self.window = window
        self.pct = pct
        self.margin = margin_s
        self.max_lead_frac = max_lead_frac
        self.update_every = update_every
        self.lead = initial_lead_s
        """Start each poll this long before its tick (seconds, before the tick cap)."""
        self.max_lead = math.inf
        self._rtt = [0.0] * window
        self._n = 0
        self.polls = 0
        self.late = 0
        """Answers that came after the tick they were timed for."""
        self.late_by_max = 0.0

    def lead_for(self, tick_period: float) -> float:
        """The lead in use for ticks of ``tick_period``."""
        self.max_lead = self.max_lead_frac * tick_period
        return min(self.lead, self.max_lead)

    def record(self, rtt: float | None, answered_at: float, tick: float) -> None:
        """One aligned poll: its round trip and answer time (rtt None: it timed out, which
        is no round trip and no late answer - the channels' health says it)."""
        self.polls += 1
        if rtt is None:
            return
        if answered_at > tick:
            self.late += 1
            if answered_at - tick > self.late_by_max:
                self.late_by_max = answered_at - tick
        self._rtt[self._n % self.window] = rtt
        self._n += 1
        n = self._n
        if n < self.update_every:  # warming up: the slowest so far
            self.lead = max(self.lead if n > 1 else 0.0, rtt + self.margin)
        elif n % self.update_every == 0:
            self.lead = self._percentile() + self.margin

    def _percentile(self) -> float:
        n = min(self._n, self.window)
        s = sorted(self._rtt[:n])
        return s[min(n - 1, int(self.pct / 100.0 * (n - 1) + 0.5))]

    def as_dict(self, state: str) -> dict[str, Any]:
        n = min(self._n, self.window)
        d: dict[str, Any] = {"state": state, "polls": self.polls, "late": self.late,
                             "late_max_ms": round(1e3 * self.late_by_max, 3)}
        if state == "aligned":
            d["lead_ms"] = round(1e3 * min(self.lead, self.max_lead), 3)
        if n:
            s = sorted(self._rtt[:n])
            d["rtt_ms"] = {"p50": round(1e3 * s[n // 2], 3),
                           "p99": round(1e3 * self._percentile(), 3)}
        return d


class ModbusAdcDriver(Driver):
    """Polls an analog-input module and emits its channels in engineering units."""

    def __init__(self, name: str, config: ModbusAdcConfig,
                 clock: Callable[[], float] = time.monotonic,
                 backoff_s: tuple[float, float] = (0.2, 5.0),
                 register_log: Callable[[RegisterRead], None] | None = None,
                 client_factory: Callable[[ModbusAdcConfig], Any] | None = None) -> None:
        super().__init__(name, clock, backoff_s)
        self.config = config
        self.register_log = register_log
        self.client_factory = client_factory
        """Builds the pymodbus-like client (default: TCP or serial client from the
        config); in-memory replays and tests pass their own."""
        self._blocks = config.channels.blocks(config.max_gap)
        self._client: Any = None
        self._next_poll: float | None = None
        self._failed_polls = 0
        self.health.extra["channels"] = chh = {c.name: _new_channel_health()
                                               for c in config.channels}
        self.health.extra["exceptions"] = 0
        self.health.extra["babbling"] = False
        self.health.extra["late_answers"] = 0
        self.health.extra["answering_late"] = False
        self._late = False
        """An answer to an earlier request came in this request's wait (it came after
        that request's timeout)."""
        self._signs = {"babbling": -math.inf, "answering_late": -math.inf}
        """When each of the two faults was last seen (the driver's clock)."""
        self.fault_hold_s = FAULT_HOLD_S
        self._garbled: str | None = None
        """What the framer threw away in the current request: an answer that was not
        Modbus (:meth:`_watch_framer`); None if nothing."""
        self._decode: Callable[[bytes], tuple[int, int, int, bytes]] | None = None
        """The RTU framer's own frame decoder (:meth:`_drain_line`); None: none watched."""
        self._watch_until = -math.inf
        """RTU: the line is watched for a late answer until then (``time.monotonic``)
        before the next request goes out (:meth:`_timed_out`)."""
        self._rtu = config.transport == "rtu"
        """No transaction id: a late answer is found by watching the line
        (:meth:`_drain_line`), and the channels are invalid while the module is late."""
        self._plan = [(address, count, chans,
                       tuple((ch.name, ch.register - address, ch.word_decoder(), chh[ch.name])
                             for ch in chans))
                      for address, count, chans in self._blocks]
        """Per block: the channels' offsets, decoders and health dicts (built once)."""
        self._channel_health = tuple(chh[c.name] for c in config.channels)
        self.tick_hint: TickHint | None = None
        """The consumer's tick grid (:meth:`align_to_ticks`); None: free-running polls."""
        self.aligner = PollAligner()
        self._target: float | None = None
        """The tick the current poll is timed for (aligned polls)."""
        self._align_state = "off"
        self._slot = 0

    def align_to_ticks(self, hint: TickHint | None, slot: int = 0) -> bool:
        """Start each poll so its answer lands just before a tick of ``hint``'s grid (a
        tick that is a poll period after the previous one, ticks ``k`` with ``k % n ==
        slot % n`` when a poll period is ``n`` ticks), instead of on the driver's own
        schedule; None restores that schedule."""
        self.tick_hint = hint
        self._slot = slot
        self._target = None
        self._align_state = "off" if hint is None else "waiting"
        if hint is None:
            self.health.extra.pop("align", None)
        else:
            self.health.extra["align"] = self.aligner.as_dict(self._align_state)
        return True

    @classmethod
    def from_config(cls, name: str, d: Mapping[str, Any], **kw: Any) -> ModbusAdcDriver:
        return cls(name, ModbusAdcConfig.from_config(d), **kw)

    # -- transport ---------------------------------------------------------------------

    def _make_client(self) -> Any:
        c = self.config
        if self.client_factory is not None:
            return self.client_factory(c)
        # pymodbus on first use: a replay on recorded registers never needs it, and it
        # is a third of the import time of ``shoveld replay --fast``
        from pymodbus.client import ModbusSerialClient, ModbusTcpClient
        from pymodbus.framer import FramerType

        from drivers.modbus_adc.strict import strict_registers

        client: ModbusTcpClient | ModbusSerialClient
        if c.transport == "tcp":
            client = ModbusTcpClient(c.host, port=int(c.port), timeout=c.timeout_s,
                                     retries=c.retries)
        else:
            client = ModbusSerialClient(
                str(c.port), framer=FramerType.RTU, baudrate=c.baudrate, parity=c.parity,
                stopbits=c.stopbits, bytesize=c.bytesize, timeout=c.timeout_s,
                retries=c.retries)
        self._watch_framer(client.framer)
        return strict_registers(client)

    def _watch_framer(self, framer: Any) -> None:
        """Count the answers that are not Modbus as bad frames of this driver. pymodbus
        drops them on its own: over TCP one whose header's protocol id is not 0 with an
        ERROR line of its logger per answer (and keeps its bytes until the request times
        out), over RTU one whose CRC fails at DEBUG; either way the request then times out,
        and the driver's health said "not answering" of a module that babbles. Here they
        are bad frames, the channels' error says what came, ``babbling`` is set (health's
        problems name it), pymodbus's line is not written, and a TCP answer's bytes are
        dropped at once. A TCP answer to an earlier request (its transaction id says so:
        the module answered after that request's timeout) is counted in ``late_answers``
        and ``answering_late`` set, where pymodbus wrote an ERROR line with a dump of the
        last frames."""
        decode, handle = framer.decode, framer.handleFrame
        tcp = self.config.transport == "tcp"
        expected = [0]
        self._decode = decode

        def watched(data: bytes) -> tuple[int, int, int, bytes]:
            if not tcp:
                used, dev, tid, frame = decode(data)
                if used and not frame:
                    self._thrown_away(used, "answers whose CRC is wrong")
                return used, dev, tid, frame
            skipped = 0
            while True:
                rest = data[skipped:] if skipped else data
                if len(rest) >= 8 and rest[2:4] != b"\0\0":
                    self._thrown_away(len(rest), "answers that are not Modbus TCP (protocol "
                                      f"id {int.from_bytes(rest[2:4], 'big')})")
                    return len(data), 0, 0, b""
                used, dev, tid, frame = decode(rest)
                if frame and tid and expected[0] and tid != expected[0]:
                    # an earlier request's answer, come after that request's timeout:
                    # pymodbus skips it with an ERROR line and a frame dump
                    self.health.extra["late_answers"] += 1
                    self._late = True
                    skipped += used
                    continue
                return used + skipped, dev, tid, frame

        def handle_frame(data: bytes, exp_devid: int, exp_tid: int) -> Any:
            expected[0] = exp_tid
            return handle(data, exp_devid, exp_tid)

        framer.decode = watched
        framer.handleFrame = handle_frame

    def _thrown_away(self, nbytes: int, what: str) -> None:
        self.health.bad_frames += 1
        self.health.rejected_bytes += nbytes
        self._garbled = what

    def _drain_line(self, client: Any, wait_s: float) -> None:
        """Over RTU, what came on the line while no request waited for it: a late answer
        (counted in ``late_answers``, ``answering_late`` set) or noise (a bad frame).
        RTU has no transaction id, so an answer that comes after its request's timeout
        would be taken as the next request's (pymodbus empties the line before a request,
        silently but for a WARNING line). As libmodbus does in its error recovery, the
        line is watched for ``wait_s`` (up to ``timeout_s`` after a timeout: the request's
        answer may still be on its way) and read before every request; an answer is taken
        as it comes, when the line has been quiet for three and a half characters (RTU's
        frame gap)."""
        sock = getattr(client, "socket", None)
        if sock is None or self._decode is None:  # an in-memory client (replays, tests)
            return
        char_s = 11.0 / self.config.baudrate
        quiet = max(0.002, 3.5 * char_s)
        now = time.monotonic()
        deadline, cap = now + wait_s, now + wait_s + 256 * char_s + quiet
        size = 0
        try:
            while True:
                avail = sock.in_waiting
                if avail and avail == size:  # came, and nothing more for a frame gap
                    break
                now = time.monotonic()
                if not avail and now >= deadline:
                    return
                if now >= cap:
                    break
                size = avail
                time.sleep(quiet)
            data = sock.read(avail)
        except (OSError, ValueError):  # the port closed or went away: the request says so
            return
        if not data:
            return
        _used, dev, _tid, frame = self._decode(data)
        if frame and dev == self.config.unit:
            self.health.extra["late_answers"] += 1
            self._late = True
        else:
            self._thrown_away(len(data), "bytes on the line between requests")

    def open(self) -> None:
        self.close()
        client = self._make_client()
        if not client.connect():
            client.close()
            raise DeviceError(f"cannot connect to Modbus module at {self.config.endpoint}")
        self._client = client
        self._failed_polls = 0
        self._next_poll = None
        self._target = None
        self._watch_until = -math.inf

    def close(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            try:
                client.close()
            except Exception:  # noqa: BLE001
                pass

    # -- polling -------------------------------------------------------------------------

    def _read_block(self, address: int, count: int) -> tuple[list[int] | None, str | None,
                                                             int | None]:
        """One request: (words, None, None) or (None, 'timeout'|'exception', code)."""
        c = self.config
        client = self._client
        if not client.connected and not client.connect():
            return None, "timeout", None
        fn = client.read_input_registers if c.function == "input" else \
            client.read_holding_registers
        self._garbled = None
        if self._rtu:
            self._drain_line(client, self._watch_until - time.monotonic())
        try:
            rr = fn(address, count=count, device_id=c.unit)
        except (TimeoutError, OSError):
            return self._timed_out()
        except Exception as e:  # noqa: BLE001 - narrowed below, pymodbus imported only now
            from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

            if isinstance(e, ModbusIOException | ConnectionException):
                return self._timed_out()
            if not isinstance(e, ModbusException):
                raise
            log.debug("%s: modbus error %s", self.name, e)
            return self._timed_out()
        if rr.isError():
            code = getattr(rr, "exception_code", None)
            return None, "exception", int(code) if code is not None else 4
        fc = getattr(rr, "function_code", c.function_code)
        regs = list(getattr(rr, "registers", []) or [])
        if fc != c.function_code or len(regs) != count:
            # An answer to another question (a holding-register reply to an input-register
            # request, or a different length) is a bad frame, not these channels' values.
            self.health.bad_frames += 1
            return None, "exception", None
        return regs, None, None

    def _timed_out(self) -> tuple[None, str, None]:
        """A request not answered within ``timeout_s``; over RTU the line is watched for
        as long again before the next request (:meth:`_drain_line`), so an answer up to
        twice the timeout late is seen late and not taken as the next request's. The
        watch waits in the next request, so this one's reading is not held back."""
        if self._rtu:
            self._watch_until = time.monotonic() + self.config.timeout_s
        return None, "timeout", None

    def poll(self, sink: Sink) -> Reading:
        """Read every block once and emit one reading (also returned)."""
        c = self.config
        values: dict[str, float] = {}
        invalid: set[str] = set()
        answered = False
        garbled = None
        self._late = False
        clock = self.clock
        isfinite = math.isfinite
        extra = self.health.extra
        rtu = self._rtu
        t = clock()
        for address, count, chans, decoders in self._plan:
            words, err, code = self._read_block(address, count)
            t = clock()
            if self.register_log is not None:
                self.register_log(RegisterRead(
                    t, c.unit, c.function_code, address, count,
                    registers=tuple(words) if words is not None else None,
                    error=err, exception_code=code))
            if err != "timeout":
                answered = True
            if words is not None and rtu and (self._late or extra["answering_late"]):
                # over RTU an answer carries nothing to say which request it answers:
                # while the module answers late, this one may be an earlier request's
                for ch in chans:
                    invalid.add(ch.name)
                    h = extra["channels"][ch.name]
                    h["state"] = "late"
                    h["last_error"] = (f"answers after the {c.timeout_s:g} s timeout: over RTU "
                                       "an answer cannot be told from an earlier one's")
                continue
            if words is not None:
                for name, offset, decode, h in decoders:
                    v = decode(words[offset])
                    if isfinite(v):
                        values[name] = v
                        h["last_ok_t"] = t
                        if h["state"] != "ok":
                            h["state"], h["last_error"] = "ok", None
                continue
            if err == "timeout":
                self.health.timeouts += 1
                garbled = self._garbled or garbled
            else:
                self.health.extra["exceptions"] += 1
            for ch in chans:
                invalid.add(ch.name)
                h = self.health.extra["channels"][ch.name]
                h["state"] = err
                if err == "timeout":
                    h["timeouts"] += 1
                    h["last_error"] = (f"no answer within {c.timeout_s:g} s" if garbled is None
                                       else f"{garbled} and no answer within {c.timeout_s:g} s")
                else:
                    h["exceptions"] += 1
                    h["last_error"] = (f"Modbus exception code {code}" if code is not None else
                                       "a reply with another function code or length")
        now = t  # receive time of the last block, taken right after its answer
        if self._late or garbled is not None or self._faulty:
            self._faults(now, garbled, answered)
        stale_after = c.stale_after_s
        for h in self._channel_health:
            last = h["last_ok_t"]
            h["stale"] = last is None or now - last > stale_after
        reading = Reading(self.name, now, values, frozenset(invalid) if invalid else _NONE)
        self.emit(sink, reading)
        self._failed_polls = 0 if answered else self._failed_polls + 1
        return reading

    @property
    def _faulty(self) -> bool:
        x = self.health.extra
        return bool(x["babbling"] or x["answering_late"])

    def _faults(self, now: float, garbled: str | None, answered: bool) -> None:
        """``babbling`` (answers that are not Modbus: a wrong baud rate or parity on RTU,
        another protocol on the port, a failing line) and ``answering_late`` (answers
        after the timeout, which land in a later request's wait: a ``timeout_s`` too short
        for the module or its gateway), each said once when it starts and once when it
        has not been seen for ``fault_hold_s`` with the module answering, so an
        intermittent fault is two lines, not two a poll."""
        x, c = self.health.extra, self.config
        for key, seen, what in (("babbling", garbled is not None, garbled),
                                ("answering_late", self._late,
                                 f"answers after the {c.timeout_s:g} s timeout")):
            if seen:
                self._signs[key] = now
                if not x[key]:
                    x[key] = True
                    log.warning("%s: Modbus module at %s %s: %s%s", self.name, c.endpoint,
                                key.replace("_", " "), what,
                                "; timeout_s too short for it?" if key == "answering_late"
                                else "")
                    self.health.last_error = f"{key.replace('_', ' ')}: {what}"
            elif x[key] and answered and now - self._signs[key] >= self.fault_hold_s:
                x[key] = False
                log.info("%s: Modbus module at %s no longer %s", self.name, c.endpoint,
                         key.replace("_", " "))

    def read(self, sink: Sink) -> None:
        if self._client is None:
            raise DeviceError("Modbus client not open")
        hint = self.tick_hint
        if hint is not None:
            grid = hint()
            if grid is not None and grid[1] <= 1.0 / self.config.poll_hz * (1.0 + 1e-9):
                self._read_aligned(sink, grid[0], grid[1])
                return
            self._set_align_state("waiting" if grid is None else "off: polls faster than ticks")
        self._read_free(sink)

    def _set_align_state(self, state: str) -> None:
        if state != self._align_state:
            self._align_state = state
            self._target = None
            self.health.extra["align"] = self.aligner.as_dict(state)

    def _read_aligned(self, sink: Sink, tick: float, tick_period: float) -> None:
        """One poll timed so that its answer lands just before a tick of the grid
        ``tick + k * tick_period`` (which the caller re-reads before every wait, so the
        polls follow a grid that moves)."""
        self._set_align_state("aligned")
        period = 1.0 / self.config.poll_hz
        clock = self.clock
        al = self.aligner
        lead = al.lead_for(tick_period)
        now = clock()
        ticks = period / tick_period
        n = round(ticks)
        whole = abs(ticks - n) < 1e-6
        if self._next_poll is None:  # where the next answer is wanted
            self._next_poll = now + lead
        if self._target is not None:  # the grid tick nearest to the wanted time
            k = round((self._next_poll - tick) / tick_period)
        else:  # the first one we can still make, in our slot
            k = math.ceil((self._next_poll - tick) / tick_period - 1e-9)
            if whole:
                k += (self._slot - k) % n
        target = tick + k * tick_period
        start = target - lead
        if now > target:  # missed it (slow answer, late thread): the next tick we can make
            k = math.ceil((now + lead - tick) / tick_period - 1e-9)
            if whole:
                k += (self._slot - k) % n
            target = tick + k * tick_period
            self._next_poll = target
            self._target = target
            return
        self._target = target
        if now < start:
            clock_wait_until(clock, start, max_real_s=0.05)
            if clock() < start:
                return  # not yet: the next read() times it again on a fresh hint
        polled = clock()
        timeouts = self.health.timeouts
        reading = self.poll(sink)
        begun = start if start > now else now
        al.record(None if self.health.timeouts != timeouts else reading.t_host - begun,
                  reading.t_host, target)
        self._next_poll = (target if whole else self._next_poll) + period
        if not whole and self._next_poll < polled - period:  # fell behind: do not burst
            self._next_poll = polled + period
        if al.polls % 50 == 0 or reading.t_host > target:
            self.health.extra["align"] = al.as_dict("aligned")
        if self._failed_polls >= self.config.reconnect_after:
            failed = self._failed_polls
            self._failed_polls = 0
            raise DeviceError(f"Modbus module at {self.config.endpoint} answered none of the "
                              f"last {failed} polls")

    def idle(self, now: float) -> bool:
        """True if :meth:`read` at ``now`` would change nothing: polling on its own schedule
        and the next poll not due (the same test as ``_read_free``'s), so a replay that
        steps the driver itself can skip the call."""
        return (self.tick_hint is None and self._next_poll is not None
                and now < self._next_poll and self._client is not None)

    def _read_free(self, sink: Sink) -> None:
        """One poll on the driver's own schedule (``poll_hz`` from the first poll)."""
        period = 1.0 / self.config.poll_hz
        now = self.clock()
        if self._next_poll is None:
            self._next_poll = now
        if now < self._next_poll:
            clock_wait_until(self.clock, self._next_poll, max_real_s=0.05)
            if self.clock() < self._next_poll:
                return
        self._next_poll += period
        now = self.clock()
        if self._next_poll < now - period:  # fell behind (slow module): do not burst
            self._next_poll = now + period
        self.poll(sink)
        if self._failed_polls >= self.config.reconnect_after:
            n = self._failed_polls
            self._failed_polls = 0
            raise DeviceError(f"Modbus module at {self.config.endpoint} answered none of the "
                              f"last {n} polls")

    def channel(self, name: str) -> Channel:
        return self.config.channels[name]
