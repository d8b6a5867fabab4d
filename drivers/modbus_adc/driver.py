"""Modbus analog-input module driver (Modbus TCP or Modbus RTU over RS-485).

Polls the module's registers at a fixed rate through pymodbus' synchronous client
and emits one :class:`~drivers.base.Reading` per poll with the channels' values
in engineering units (the signals-table column names: ``hoist1_a``,
``boom_deg``, ...). A channel whose block timed out or was answered with a Modbus
exception is listed in ``Reading.invalid`` and *not* in ``values``: the previous
good value is never repeated as if it were new, and nothing becomes zero.

Per-channel health lives in ``health.extra["channels"][name]``: ``state``
(``ok`` / ``timeout`` / ``exception`` / ``never``), ``timeouts``, ``exceptions``,
``last_ok_t`` and ``stale`` (no good value for ``stale_after_s``).
After ``reconnect_after`` consecutive polls the module did not answer at all, ``read``
raises :class:`~drivers.base.DeviceError` and the base class reconnects with
back-off.

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

from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.framer import FramerType

from drivers.base import DeviceError, Driver, Reading, Sink
from drivers.capture.clock import clock_wait_until
from drivers.capture.format import RegisterRead
from drivers.modbus_adc.channels import Channel, ChannelMap

log = logging.getLogger(__name__)


class _NoResponseFilter(logging.Filter):
    """pymodbus logs every unanswered request at ERROR with a frame dump; the driver
    reports timeouts per channel in its health, so that line is noise here."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.getMessage()).startswith("No response received")


logging.getLogger("pymodbus.logging").addFilter(_NoResponseFilter())

_FUNCTIONS = {"input": 4, "holding": 3}
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
        for k in d:
            if k not in allowed:
                raise ValueError(f"{kind}: unknown key {k!r}; known keys: {sorted(allowed)}")
        if "channels" not in d:
            raise ValueError(f"{kind}: key 'channels' is required (list of channel tables)")
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
        self._plan = [(address, count, chans,
                       tuple((ch.name, ch.register - address, ch.word_decoder(), chh[ch.name])
                             for ch in chans))
                      for address, count, chans in self._blocks]
        """Per block: the channels' offsets, decoders and health dicts (built once)."""
        self._channel_health = tuple(chh[c.name] for c in config.channels)

    @classmethod
    def from_config(cls, name: str, d: Mapping[str, Any], **kw: Any) -> ModbusAdcDriver:
        return cls(name, ModbusAdcConfig.from_config(d), **kw)

    # -- transport ---------------------------------------------------------------------

    def _make_client(self) -> Any:
        c = self.config
        if self.client_factory is not None:
            return self.client_factory(c)
        if c.transport == "tcp":
            return ModbusTcpClient(c.host, port=int(c.port), timeout=c.timeout_s,
                                   retries=c.retries)
        return ModbusSerialClient(str(c.port), framer=FramerType.RTU, baudrate=c.baudrate,
                                  parity=c.parity, stopbits=c.stopbits, bytesize=c.bytesize,
                                  timeout=c.timeout_s, retries=c.retries)

    def open(self) -> None:
        self.close()
        client = self._make_client()
        if not client.connect():
            client.close()
            raise DeviceError(f"cannot connect to Modbus module at {self.config.endpoint}")
        self._client = client
        self._failed_polls = 0
        self._next_poll = None

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
        try:
            rr = fn(address, count=count, device_id=c.unit)
        except (ModbusIOException, ConnectionException, TimeoutError, OSError):
            return None, "timeout", None
        except ModbusException as e:
            log.debug("%s: modbus error %s", self.name, e)
            return None, "timeout", None
        if rr.isError():
            code = getattr(rr, "exception_code", None)
            return None, "exception", int(code) if code is not None else 4
        regs = list(getattr(rr, "registers", []) or [])
        if len(regs) < count:
            return None, "exception", 3
        return regs[:count], None, None

    def poll(self, sink: Sink) -> Reading:
        """Read every block once and emit one reading (also returned)."""
        c = self.config
        values: dict[str, float] = {}
        invalid: set[str] = set()
        answered = False
        clock = self.clock
        isfinite = math.isfinite
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
            else:
                self.health.extra["exceptions"] += 1
            for ch in chans:
                invalid.add(ch.name)
                h = self.health.extra["channels"][ch.name]
                h["state"] = err
                if err == "timeout":
                    h["timeouts"] += 1
                    h["last_error"] = f"no answer within {c.timeout_s:g} s"
                else:
                    h["exceptions"] += 1
                    h["last_error"] = f"Modbus exception code {code}"
        now = t  # receive time of the last block, taken right after its answer
        stale_after = c.stale_after_s
        for h in self._channel_health:
            last = h["last_ok_t"]
            h["stale"] = last is None or now - last > stale_after
        reading = Reading(self.name, now, values, frozenset(invalid) if invalid else _NONE)
        self.emit(sink, reading)
        self._failed_polls = 0 if answered else self._failed_polls + 1
        return reading

    def read(self, sink: Sink) -> None:
        if self._client is None:
            raise DeviceError("Modbus client not open")
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
