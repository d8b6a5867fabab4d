"""A real pymodbus server whose register values come from a callback.

Both the ADC emulator (values from a signals table) and capture replay (values
from recorded reads) need a Modbus slave that answers with *current* values, can
answer with an exception, and can stay silent. pymodbus' ``SimDevice`` action hook
fills the registers on every request; a packet trace hook drops the response when
the provider asks for silence, so the client really times out.

Transports: Modbus TCP on ``127.0.0.1`` with a free port chosen by the OS, and
Modbus RTU over a pseudo-terminal (two pty pairs bridged by a thread: pymodbus
opens one slave path, the driver the other, as it would a USB RS-485 adapter).
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerType
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.capture.ptylink import PtyLink, open_pty_link

log = logging.getLogger(__name__)


class _ClientLeft(logging.Filter):
    """pymodbus's server logs at ERROR, with a dump of its last twenty frames, an answer
    it cannot send because the client has gone (a driver that timed out and reconnects
    while a late answer was pending): a module does not notice that either, and the
    driver says what it saw. Seen in the fault drill's output; only this server's
    threads (``modbus-*``) are quieted."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not (record.threadName is not None and record.threadName.startswith("modbus-")
                    and str(record.getMessage()).startswith("Cancel send"))


logging.getLogger("pymodbus.logging").addFilter(_ClientLeft())

Provider = Callable[[int, int, int], "list[int] | int | None"]
"""``(function_code, address, count) -> words | exception_code | None``.

``words``: ``count`` register words (0..65535) to answer with; an ``int``: a
Modbus exception code to answer with (e.g. 4 = server device failure); ``None``:
send nothing (the client times out).
"""


class RegisterServer:
    """Background-thread pymodbus server (TCP or RTU-over-pty) answering from ``provider``."""

    def __init__(self, provider: Provider, *, transport: str = "tcp", unit: int = 1,
                 host: str = "127.0.0.1", port: int = 0, baudrate: int = 19200,
                 registers: int = 1024) -> None:
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"transport must be 'tcp' or 'rtu', got {transport!r}")
        self.provider = provider
        self.transport = transport
        self.unit = unit
        self.host = host
        self.port: int = port
        """TCP: the bound port (known after :meth:`start`)."""
        self.serial_port: str | None = None
        """RTU: the pty path the driver opens (known after :meth:`start`)."""
        self.baudrate = baudrate
        self.registers = registers
        self.silent = False
        """True: receive requests but never answer (module hung, cable cut)."""
        self.delay_s = 0.0
        """Each answer is sent this late (a module busy with its conversions, a slow
        gateway): past the client's timeout it lands in the next request's wait."""
        self.garble: Callable[[bytes], bytes] | None = None
        """Each answer's bytes are sent through this (noise on the line, a wrong baud
        rate, a device that speaks another protocol); None: sent as they are."""
        self.requests = 0
        self.in_flight = False
        self.last_request_t: float | None = None
        self.on_request: Callable[[int, int, int], None] | None = None
        self.drop_hold_s = 0.0
        """After dropping an answer, ``hold_until`` is set this far ahead (the client's
        timeout): replay keeps a stepped clock still while the client waits it out."""
        self.hold_until = 0.0
        self._drop_next = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: Any = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._links: list[PtyLink] = []
        self._bridge_stop = threading.Event()
        self._bridge: threading.Thread | None = None

    # -- pymodbus hooks --------------------------------------------------------------------

    async def _action(self, fc: int, start: int, address: int, count: int,
                      regs: list[int], values: Any) -> Any:
        self.requests += 1
        if self.delay_s > 0:
            await asyncio.sleep(self.delay_s)
        if self.on_request is not None:
            self.on_request(fc, address, count)
        if values is not None:  # writes are not part of the emulated module
            return ExcCodes.ILLEGAL_FUNCTION
        try:
            res = self.provider(fc, address, count)
        except Exception:  # noqa: BLE001 - a broken provider answers like a broken module
            log.exception("register provider failed")
            res = 0x04
        if res is None or self.silent:
            self._drop_next = True
            return None
        if isinstance(res, int):
            try:
                return ExcCodes(res)
            except ValueError:
                return ExcCodes.DEVICE_FAILURE
        off = address - start
        for i, w in enumerate(res[:count]):
            regs[off + i] = int(w) & 0xFFFF
        return None

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if sending:
            self.in_flight = False
            if self._drop_next or self.silent:
                self._drop_next = False
                self.hold_until = time.monotonic() + self.drop_hold_s
                return b""
            if self.garble is not None:
                return self.garble(data)
        else:
            self.in_flight = True
            self.hold_until = 0.0
        return data

    # -- lifecycle -----------------------------------------------------------------------

    def start(self, timeout: float = 5.0) -> RegisterServer:
        """Serve; after :meth:`stop`, serve again on the same TCP port (a module powered
        off and on again; over RTU the pty paths are new)."""
        self._ready.clear()
        self._error = None
        self._bridge_stop.clear()
        if self.transport == "rtu":
            a, b = open_pty_link(), open_pty_link()
            self._links = [a, b]
            self.serial_port = b.slave_path
            self._bridge = threading.Thread(target=self._run_bridge, name="modbus-rtu-bridge",
                                            daemon=True)
            self._bridge.start()
        self._thread = threading.Thread(target=self._run, name=f"modbus-{self.transport}-server",
                                        daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise RuntimeError("Modbus server did not start")
        if self._error is not None:
            raise RuntimeError(f"Modbus server failed to start: {self._error}")
        return self

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._serve())
            loop.run_forever()
        except BaseException as e:  # noqa: BLE001
            self._error = e
            self._ready.set()
        finally:
            try:
                loop.run_until_complete(loop.shutdown_asyncgens())
            except Exception:  # noqa: BLE001
                pass
            loop.close()

    async def _serve(self) -> None:
        device = SimDevice(
            id=0, simdata=[SimData(0, count=self.registers, values=0,
                                   datatype=DataType.REGISTERS)],
            action=self._action)
        if self.transport == "tcp":
            self._server = ModbusTcpServer(device, address=(self.host, self.port),
                                           trace_packet=self._trace_packet)
        else:
            self._server = ModbusSerialServer(device, framer=FramerType.RTU,
                                              port=self._links[0].slave_path,
                                              baudrate=self.baudrate,
                                              trace_packet=self._trace_packet)
        await self._server.serve_forever(background=True)
        if self.transport == "tcp":
            srv = getattr(self._server, "transport", None)
            socks = getattr(srv, "sockets", None) or []
            if socks:
                self.port = int(socks[0].getsockname()[1])
        self._ready.set()

    def _run_bridge(self) -> None:
        """Copy bytes between the two pty masters, as a null-modem cable would."""
        import select

        a, b = self._links
        while not self._bridge_stop.is_set():
            r, _, _ = select.select([a.master_fd, b.master_fd], [], [], 0.05)
            for src, dst in ((a, b), (b, a)):
                if src.master_fd in r:
                    data = src.read(0)
                    if data:
                        dst.write(data, timeout_s=0.2)

    def stop(self) -> None:
        loop, server = self._loop, self._server
        if loop is not None and server is not None and not loop.is_closed():
            async def _shutdown() -> None:
                await server.shutdown()
                await asyncio.sleep(0)
                loop.stop()
            try:
                asyncio.run_coroutine_threadsafe(_shutdown(), loop).result(timeout=3)
            except Exception:  # noqa: BLE001
                loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(timeout=3)
        self._bridge_stop.set()
        if self._bridge is not None:
            self._bridge.join(timeout=2)
        for link in self._links:
            link.close()

    def __enter__(self) -> RegisterServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
