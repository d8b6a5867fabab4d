"""A site's Zenoh router as a process of its own, to start, stop and start again.

The daemon's tests and the fault drill need a router that goes away the way a real one
does (its process ends, its sockets close; or it hangs with its sockets open) and comes
back on the same endpoint: a Zenoh session in router mode in a child interpreter,
stopped by closing its stdin, hung and resumed by SIGSTOP and SIGCONT. A plain one has
the site router's lease and admin space (``shoveld pki router-config``'s), which decide
when a hung one is seen; ``admin=False`` closes the admin space, as a router configured
by hand may have it, so that the probe gets no answer (a client still hears its
questions' ends; a peer among other routers or peers is left to the lease).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

from shoveld.security.acl import ADMINSPACE, lease

ROUTER = """
import json, sys, zenoh
if sys.argv[1].endswith(".json5"):
    c = zenoh.Config.from_file(sys.argv[1])
else:
    c = zenoh.Config()
    c.insert_json5("mode", '"router"')
    c.insert_json5("listen/endpoints", json.dumps([sys.argv[1]]))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("transport/link/tx", sys.argv[2])
    if sys.argv[3] != "null":
        c.insert_json5("adminspace", sys.argv[3])
s = zenoh.open(c)
print("up", flush=True)
sys.stdin.read()
s.close()
"""


def start_router(endpoint_or_config: str | Path, admin: bool = True) -> subprocess.Popen[str]:
    """A router process (a plain ``tcp/`` one on an endpoint, or from a config file
    ``*.json5``), once it listens; stop it with ``communicate("")``."""
    r = subprocess.Popen([sys.executable, "-c", ROUTER, str(endpoint_or_config),
                          json.dumps(lease()), json.dumps(ADMINSPACE if admin else None)],
                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert r.stdout is not None
    line = r.stdout.readline().strip()
    if line != "up":
        r.kill()
        r.wait()
        raise RuntimeError(f"the router on {endpoint_or_config} did not start ({line!r})")
    return r


class Router:
    """A router on one endpoint that can be stopped and started again (a site router
    restarted, or switched off and on)."""

    def __init__(self, endpoint_or_config: str | Path, admin: bool = True) -> None:
        self.where = endpoint_or_config
        self.admin = admin
        self.proc: subprocess.Popen[str] | None = None
        self.hung = False

    def start(self) -> Router:
        if self.proc is None:
            self.proc = start_router(self.where, self.admin)
        return self

    def stop(self) -> None:
        self.resume()  # a stopped process cannot read its stdin's end
        proc, self.proc = self.proc, None
        if proc is not None:
            proc.communicate("", timeout=10)

    def hang(self) -> None:
        """Stop answering with its sockets open (a hung router, or one cut off)."""
        if self.proc is not None:
            os.kill(self.proc.pid, signal.SIGSTOP)
            self.hung = True

    def resume(self) -> None:
        if self.proc is not None and self.hung:
            os.kill(self.proc.pid, signal.SIGCONT)
        self.hung = False

    def __enter__(self) -> Router:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
