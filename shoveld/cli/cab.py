"""``shoveld cab``: the operator's view in a terminal, from Zenoh.

Subscribes to a shovel's ``payload/live``, ``pass``, ``truck`` and ``health`` topics
and watches the daemon's liveliness token. Whenever that token appears - at start, after
the daemon restarts, after the network or a router comes back - it asks ``status``, so
a display switched on mid-truck, or cut off while passes were made, shows every pass of
the current truck (Zenoh does not re-send what was published while it was away; the
daemon's pass log has it). On a terminal it redraws
one screen with plain ANSI codes; when stdout is not a terminal (a log, a pipe) it
prints one line per event instead.
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from shoveld.cli import CliError
from shoveld.cli.options import COUNT, KEY_PREFIX, SECONDS, SHOVEL_OR_ALL
from shoveld.daemon.router_probe import RouterProbe
from shoveld.endpoints import endpoint_arg
from shoveld.payload.trucks import passes_words
from shoveld.words import n_of

if TYPE_CHECKING:
    from shoveld.daemon.config import TlsConfig

log = logging.getLogger("shoveld.cab")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "cab", help="cab display: live payload, passes of the truck, truck total",
        description="A Zenoh subscriber for the cab: live payload, the passes of the current "
                    "truck and the truck total against target. Connects to the daemon on "
                    "this machine by default.")
    p.add_argument("--connect", action="append", default=None, metavar="ENDPOINT",
                   type=endpoint_arg,
                   help="Zenoh endpoint to connect to (repeatable; default "
                        "tcp/127.0.0.1:7447)")
    p.add_argument("--mode", choices=("client", "peer"), default="client")
    p.add_argument("--shovel", type=SHOVEL_OR_ALL, default="*",
                   help="shovel id to show (default: all)")
    p.add_argument("--prefix", type=KEY_PREFIX, default="shovel",
                   help="key prefix (zenoh.prefix)")
    p.add_argument("--duration", type=SECONDS, default=None, help="exit after this many seconds")
    p.add_argument("--lines", action="store_true",
                   help="print one line per event even on a terminal")
    p.add_argument("--until-closed-trucks", type=COUNT, default=None, metavar="N",
                   help="exit after N trucks were closed (demo, tests)")
    add_tls_arg(p)
    p.add_argument("--web", action="store_true",
                   help="serve the cab page (a kiosk browser on the cab panel opens it) "
                        "instead of drawing in the terminal")
    p.add_argument("--listen", default=None, metavar="HOST:PORT",
                   help="address of the page with --web (default 127.0.0.1:8080)")
    p.set_defaults(func=run)


def add_tls_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--tls", nargs=3, metavar=("CA", "CERT", "KEY"), default=None,
                   help="mutual TLS with the site CA: its certificate, this display's "
                        "certificate and key (from 'shoveld pki issue NAME --role cab')")


def tls_from_args(args: argparse.Namespace) -> TlsConfig | None:
    if not args.tls:
        return None
    from shoveld.daemon.config import TlsConfig
    from shoveld.security.pki import PkiError, check_peer_files

    ca, certificate, key = (Path(x) for x in args.tls)
    tls = TlsConfig(ca, certificate, key)
    for x in tls.ca, tls.certificate, tls.key:
        if not x.is_file():
            raise CliError(f"--tls: {x}: no such file")
    # what a handshake would refuse without saying why: another site's CA, another
    # peer's key, a key other users may read, a certificate out of date
    try:
        check_peer_files(tls.ca, tls.certificate, tls.key)
    except PkiError as e:
        raise CliError(f"--tls: {e}") from None
    return tls


def run_web(args: argparse.Namespace, page: str) -> int:
    """``--web``: the page server with its Zenoh bridge (``shoveld.web``)."""
    from shoveld.web.server import ZenohSource, parse_listen, run_screen

    listen = args.listen or "127.0.0.1:8080"
    try:
        host, port = parse_listen(listen)
    except ValueError as e:
        raise CliError(str(e)) from None
    src = ZenohSource(args.connect or ["tcp/127.0.0.1:7447"], args.mode, args.shovel,
                      args.prefix, tls_from_args(args))
    try:
        run_screen(src, host, port, page, args.duration)
    except OSError as e:
        raise CliError(f"--listen {listen}: {e.strerror or e}") from None
    return 0


TOPICS = frozenset({"payload/live", "pass", "truck", "health"})


def _truck_word(t: dict[str, Any]) -> str:
    """A truck's status as an operator should read it: "under" only once it is sent off."""
    status = str(t.get("status") or "")
    return status if t.get("closed") or status.startswith("over") else "loading"


def _doubt(p: dict[str, Any]) -> str:
    """A weighed pass the daemon marked ``misfit_high`` (the model did not fit it): its
    weight may be off, which the cab says beside it ("" for the others)."""
    if not (p.get("valid") and p.get("misfit_high")):
        return ""
    m = p.get("misfit")
    return f"  ? model did not fit (misfit {m:.1f})" if isinstance(m, (int, float)) else \
        "  ? model did not fit"


def _or_dash(v: Any) -> str:
    """A value the screen shows, or "-" where the message left it out."""
    return "-" if v is None else str(v)


def _kg_or_dash(kg: float | None) -> str:
    """Kilograms to the kilogram, or "-" where the message left them out (never 0)."""
    return "-" if kg is None else f"{kg:.0f}"


def _live_doubt(live: dict[str, Any]) -> str:
    """A live estimate made while the crowd is in doubt (the daemon's ``crowd_doubt``:
    its laser's gap or change of target) says so beside its number ("" otherwise)."""
    d = live.get("crowd_doubt")
    return f"  ? crowd laser {d}: checked at the dump" if d else ""


def _load(t: dict[str, Any]) -> str:
    """A truck message's passes and load: "3 passes, 68000 of 136000 kg", and with a pass
    not weighed "3 passes (1 not weighed), at least 68000 of 136000 kg"."""
    passes, least = passes_words(t)
    return f"{passes}, {least}{t.get('total_kg') or 0:.0f} of {t.get('target_kg') or 0:.0f} kg"


def _weight(m: dict[str, Any]) -> str | None:
    """A valid estimate's "31027 kg +- 91 kg" (its spread left out if not sent); None
    for one not valid or without a payload."""
    p, s = m.get("payload_kg"), m.get("std_kg")
    if not m.get("valid") or p is None:
        return None
    return f"{p:.0f} kg" + (f" +- {s:.0f} kg" if s is not None else "")


def _kg(x: Any) -> str:
    return "     --" if x is None else f"{x:7.0f}"


@dataclass
class ShovelView:
    """What the cab knows about one shovel."""

    shovel: str
    alive: bool = False
    live: dict[str, Any] | None = None
    truck: dict[str, Any] | None = None
    passes: list[dict[str, Any]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    closed: list[dict[str, Any]] = field(default_factory=list)


class CabState:
    """Cab state from messages (no Zenoh here, so it is tested directly)."""

    keeps_lines = True
    """Whether events become lines for ``--lines`` (:meth:`take_lines`); the web screens,
    which draw everything from their snapshot, keep none."""

    def __init__(self) -> None:
        self.shovels: dict[str, ShovelView] = {}
        self.lock = threading.Lock()
        self.lines: list[str] = []
        """Line-mode output waiting to be printed."""
        self._last_phase: dict[str, str] = {}
        self.closed_trucks = 0
        self.bad_messages: dict[str, int] = {}
        """Per shovel, the messages refused for a field of another kind (or not JSON)."""
        self.link = "connecting"
        """This screen's Zenoh link: ``connecting`` (no session yet), ``up`` or ``down``
        (the session open, nothing reached through it: :func:`watch_link`)."""
        self.link_detail = ""

    def set_link(self, link: str, detail: str = "") -> None:
        """The link's state; a change between up and down is a line of its own."""
        with self.lock:
            was = self.link
            self.link, self.link_detail = link, detail
            if link != was and "down" in (link, was):
                self._say(f"{time.strftime('%H:%M:%S')} zenoh: link {link}"
                          + (f": {detail}" if link == "down" else ""))

    def on_bad_message(self, shovel: str, topic: str, problem: str) -> None:
        """A message the screens cannot take: counted, and said in the log the first
        time for its shovel and every hundredth after (not one line each)."""
        with self.lock:
            n = self.bad_messages[shovel] = self.bad_messages.get(shovel, 0) + 1
        if n == 1 or n % 100 == 0:
            log.warning("%s: %s from shovel %s refused (%s); %d so far", topic,
                        "message" if topic != "status" else "answer", shovel, problem, n)

    def refused_note(self, shovel: str) -> str | None:
        """What the screen says of the messages it refused from ``shovel`` (None if
        none): on the screen, not only in the log, for whoever looks at it."""
        n = self.bad_messages.get(shovel, 0)
        if not n:
            return None
        return (f"screen: {n_of(n, 'message', 'messages')} from this shovel refused "
                "(fields of another kind: another version of the daemon?)")

    def view(self, shovel: str) -> ShovelView:
        v = self.shovels.get(shovel)
        if v is None:
            v = self.shovels[shovel] = ShovelView(shovel)
        return v

    def on_message(self, shovel: str, topic: str, msg: dict[str, Any]) -> None:
        with self.lock:
            v = self.view(shovel)
            v.alive = True
            stamp = time.strftime("%H:%M:%S", time.localtime(msg.get("time") or msg.get("end")
                                                             or time.time()))
            if topic == "payload/live":
                v.live = msg
                ph = msg.get("phase") or "?"
                if self._last_phase.get(shovel) != ph:
                    self._last_phase[shovel] = ph
                    w = _weight(msg)
                    val = f"{w}{_live_doubt(msg)}" if w else "no valid estimate"
                    self._say(f"{stamp} {shovel} {ph:7s} live {val}")
            elif topic == "pass":
                if not any(p.get("pass") == msg.get("pass") for p in v.passes):
                    if v.truck and v.truck.get("truck") != msg.get("truck"):
                        v.passes = []
                    v.passes.append(msg)
                val = _weight(msg) or ("INVALID" + (f" ({r})" if (r := msg.get("reason"))
                                                    else ""))
                self._say(f"{stamp} {shovel} pass {msg.get('pass')} truck "
                          f"{msg.get('truck')}: {val}{_doubt(msg)}")
            elif topic == "truck":
                if msg.get("closed"):
                    v.closed.append(msg)
                    self.closed_trucks += 1
                else:
                    if v.truck and v.truck.get("truck") != msg.get("truck"):
                        v.passes = [p for p in v.passes if p.get("truck") == msg.get("truck")]
                    v.truck = msg
                self._say(
                    f"{time.strftime('%H:%M:%S')} {shovel} truck {msg.get('truck')}"
                    f"{' CLOSED' if msg.get('closed') else ''}: {_load(msg)} "
                    f"({msg.get('fill_pct')} %) {_truck_word(msg)}")
            elif topic == "health":
                probs = list(msg.get("problems") or [])
                if probs != v.problems:
                    self._say(f"{time.strftime('%H:%M:%S')} {shovel} health: "
                              + ("; ".join(probs) if probs else "all ok"))
                v.problems = probs

    def on_status(self, shovel: str, st: dict[str, Any]) -> None:
        """The daemon's answer to ``status``: its current truck and the passes in it. A
        pass of that truck heard after the daemon answered is kept."""
        with self.lock:
            v = self.view(shovel)
            v.alive = True
            truck = st.get("truck")
            if truck:
                newer = (v.truck is not None and v.truck.get("truck") == truck.get("truck")
                         and (v.truck.get("passes") or 0) > (truck.get("passes") or 0))
                if not newer:
                    v.truck = truck
            passes = {p.get("pass"): p for p in st.get("truck_passes") or []}
            number = (truck or {}).get("truck")
            for p in v.passes:
                if p.get("truck") == number and p.get("pass") not in passes:
                    passes[p.get("pass")] = p
            v.passes = sorted(passes.values(), key=lambda p: p.get("pass") or 0)
            if st.get("live"):
                v.live = st["live"]
            v.problems = list(st.get("problems") or [])
            self._say(f"{time.strftime('%H:%M:%S')} {shovel} status: truck "
                      f"{(st.get('truck') or {}).get('truck')}, "
                      f"{n_of(len(v.passes), 'pass', 'passes')} so far")

    def on_alive(self, shovel: str, alive: bool) -> None:
        with self.lock:
            self.view(shovel).alive = alive
            self._say(f"{time.strftime('%H:%M:%S')} {shovel} daemon "
                      f"{'alive' if alive else 'LOST'}")

    def _say(self, line: str) -> None:
        """A line for ``--lines`` (the caller holds the lock)."""
        if self.keeps_lines:
            self.lines.append(line)

    def take_lines(self) -> list[str]:
        with self.lock:
            out, self.lines = self.lines, []
        return out

    def screen(self, width: int = 72) -> str:
        """The whole cab screen as text, ``width`` columns wide (the terminal's)."""
        from shoveld.web.state import last_pass_hint, truck_warning

        width = max(40, width)
        out: list[str] = []
        with self.lock:
            if self.link == "down":
                out.append(f"!! zenoh: {self.link_detail}")
            if not self.shovels:
                return "\n".join([*out, "waiting for a shovel on Zenoh ...", ""])
            for name in sorted(self.shovels):
                v = self.shovels[name]
                out.append(f"== {name} " + ("" if v.alive else "(daemon not seen) ")
                           + "=" * max(0, width - len(name) - 4 - (0 if v.alive else 18)))
                lv = v.live or {}
                if lv.get("valid") and lv.get("payload_kg") is not None:
                    sd = lv.get("std_kg")  # its spread left out if not sent, as _weight does
                    val = (f"{lv['payload_kg']:8.0f} kg"
                           + (f"  +- {sd:.0f} kg" if sd is not None else "") + _live_doubt(lv))
                else:
                    val = "      -- (no valid estimate)"
                out.append(f"  phase {lv.get('phase') or '?':7s}  live payload {val}")
                t = dict(v.truck or {})
                if v.closed and t and v.closed[-1].get("truck") == t.get("truck"):
                    t = dict(v.closed[-1])
                target = float(t.get("target_kg") or 0.0)
                total = float(t.get("total_kg") or 0.0)
                nw = int(t.get("invalid_passes") or 0)
                status = str(t.get("status") or "")
                # A truck being loaded is not "under" yet: say so only once it is sent off.
                word = ("sent off, " + status.upper() if t.get("closed") else
                        "OVER" if status.startswith("over") else "loading")
                out.append(f"  truck {t.get('truck', '?')}: {_load(t)} "
                           f"({t.get('fill_pct', 0)} %)  {word}")
                if target and not t.get("closed"):
                    recent = [float(p["payload_kg"]) for p in v.passes[-10:]
                              if p.get("valid") and p.get("payload_kg") is not None]
                    hint = last_pass_hint(total, target, recent, nw)
                    left = hint["remaining_kg"]
                    if left is not None:
                        out.append(f"  still to go {max(left, 0.0):.0f} kg" if left > 0 else
                                   f"  over target by {-left:.0f} kg")
                    out.append("  " + hint["text"])
                warn = truck_warning(t)
                if warn:
                    out.append(f"  !! {warn['text']}")
                fill = min(1.3, total / (target or 1.0))
                bar_w = width - 12
                k = int(bar_w * fill / 1.3)
                marks = {int(bar_w * f / 1.3) for f in (1.0, 1.1, 1.2)}
                bar = "".join("#" if i < k else ("|" if i in marks else ".")
                              for i in range(bar_w))
                out.append(f"  [{bar}]")
                mine = [p for p in v.passes if p.get("truck") == t.get("truck")]
                for i, p in enumerate(mine, start=1):
                    if i <= len(mine) - 8:
                        continue
                    if p.get("valid"):
                        out.append(f"    pass {i:2d}  {_kg(p.get('payload_kg'))} kg"
                                   f"  +- {p.get('std_kg') or 0:5.0f} kg{_doubt(p)}")
                    else:
                        out.append(f"    pass {i:2d}  INVALID  {p.get('reason', '')}")
                if v.closed:
                    c = v.closed[-1]
                    cw = int(c.get("invalid_passes") or 0)
                    kg, pct = _kg_or_dash(c.get("total_kg")), _or_dash(c.get("fill_pct"))
                    out.append(f"  last truck {_or_dash(c.get('truck'))}: "
                               + (f"at least {kg} kg ({pct} %), {cw} not weighed" if cw
                                  else f"{kg} kg ({pct} %) {c.get('status') or ''}"))
                    # (their fields' kinds are checked on arrival; a field may be absent)
                    r = c.get("rule_10_10_20") or {}
                    sh = c.get("shift") or {}
                    if sh.get("trucks"):
                        t_kg = "-" if sh.get("kg") is None else f"{sh['kg'] / 1000:.1f}"
                        out.append(f"  shift so far: {n_of(sh['trucks'], 'truck', 'trucks')}, "
                                   f"{n_of(sh.get('passes') or 0, 'pass', 'passes')}, {t_kg} t")
                    if r.get("trucks"):
                        nj = int(r.get("not_judged") or 0)
                        out.append(f"  shift: {n_of(r['trucks'], 'truck', 'trucks')}, "
                                   f"mean fill {_or_dash(r.get('mean_pct'))} %, "
                                   f"{_or_dash(r.get('over_110_pct'))} % over 110 %, "
                                   f"{r.get('over_120') or 0} over 120 % "
                                   f"({'no overload beyond' if r.get('compliant') else 'OUTSIDE'}"
                                   " the 10/10/20 rule)"
                                   + (f"; {nj} with a pass not weighed not judged" if nj else ""))
                    elif r.get("not_judged"):
                        out.append(f"  shift: no truck judged: "
                                   f"{n_of(r['not_judged'], 'truck', 'trucks')} with a pass "
                                   "not weighed" + (f"; {r['over_120']} over 120 %, OUTSIDE the "
                                                    "10/10/20 rule" if r.get("over_120") else ""))
                problems = list(v.problems)
                if (note := self.refused_note(name)) is not None:
                    problems.append(note)
                if problems:
                    out.append("  ! " + "; ".join(problems)[: width * 2])
                out.append("")
        return "\n".join(out) + "\n"


class CabClient:
    """The Zenoh side of the cab: subscriptions, liveliness, the status query."""

    def __init__(self, state: CabState, connect: list[str], mode: str = "client",
                 shovel: str = "*", prefix: str = "shovel",
                 tls: TlsConfig | None = None, topics: frozenset[str] = TOPICS) -> None:
        import zenoh

        from shoveld.daemon.messages import message_problem
        from shoveld.daemon.publisher import zenoh_config

        self.state = state
        self.prefix = prefix
        self.shovel = shovel
        self.session = zenoh.open(zenoh_config(mode, (), connect, tls=tls))
        self.probe = RouterProbe(self.session).start()
        """Sees a router that hangs or is cut off sooner than its lease (:meth:`reaches`)."""
        n = len(prefix.split("/"))
        self._n = n

        def on_sample(sample: Any) -> None:
            key = str(sample.key_expr).split("/")
            topic = "/".join(key[n + 1:])
            if topic not in topics:
                return
            try:
                msg = json.loads(sample.payload.to_bytes())
            except ValueError:
                state.on_bad_message(key[n], topic, "not JSON")
                return
            problem = message_problem(msg)
            if problem is not None:
                state.on_bad_message(key[n], topic, problem)
                return
            state.on_message(key[n], topic, msg)

        base = f"{prefix}/{shovel}"
        # one subscriber for every topic: samples from one shovel arrive in the order
        # they were put (a pass before the truck it completes)
        self._subs = [self.session.declare_subscriber(f"{base}/**", on_sample)]

        def on_alive(sample: Any) -> None:
            key = str(sample.key_expr).split("/")
            alive = sample.kind == zenoh.SampleKind.PUT
            state.on_alive(key[n], alive)
            if alive:  # (re)appeared: catch up on what was missed, off Zenoh's callback thread
                threading.Thread(target=self.query_status, args=(2.0, key[n]),
                                 name="cab-status", daemon=True).start()

        self._subs.append(self.session.liveliness().declare_subscriber(
            f"{base}/alive", on_alive, history=True))

    def query_status(self, timeout: float = 2.0, shovel: str | None = None) -> int:
        """Ask ``status`` of one shovel (default: the ones shown); returns the answers."""
        from shoveld.daemon.messages import status_problem

        n = 0
        key = f"{self.prefix}/{shovel or self.shovel}/status"
        try:
            replies = self.session.get(key, timeout=timeout)
        except Exception:  # noqa: BLE001 - session closed while a catch-up query was due
            return 0
        for reply in replies:
            if reply.ok is None:
                continue
            parts = str(reply.ok.key_expr).split("/")
            try:
                st = json.loads(reply.ok.payload.to_bytes())
            except ValueError:
                self.state.on_bad_message(parts[self._n], "status", "not JSON")
                continue
            problem = status_problem(st)
            if problem is not None:
                self.state.on_bad_message(parts[self._n], "status", problem)
                continue
            self.state.on_status(parts[self._n], st)
            n += 1
        return n

    def reaches(self) -> int:
        """The routers and peers this session reaches now (a screen listens on nothing:
        all it hears comes through what it connects to); -1 if Zenoh cannot say. Routers
        that have stopped answering the probe are not counted."""
        from shoveld.daemon.publisher import count_links

        try:
            links = count_links(self.session)
        except Exception:  # noqa: BLE001 - a closed session
            return -1
        if self.probe.silent():
            links["routers"] = 0
        return sum(links.values())

    def close(self) -> None:
        self.probe.close()
        for s in self._subs:
            try:
                s.undeclare()
            except Exception:  # noqa: BLE001
                pass
        self.session.close()


def show(state: CabState, out: TextIO, tty: bool, stop: threading.Event,
         duration: float | None = None, until_closed: int | None = None,
         refresh_s: float = 0.25) -> None:
    """Redraw (TTY) or print lines until stopped, ``duration`` or ``until_closed``."""
    end = None if duration is None else time.monotonic() + duration
    if tty:
        out.write("\x1b[?25l")  # hide the cursor
    try:
        while not stop.is_set():
            if tty:
                state.take_lines()
                # Home the cursor and overwrite line by line, clearing each line's rest and
                # what is below: the screen never blanks, so it does not flicker.
                cols = shutil.get_terminal_size((80, 24)).columns
                text = state.screen(cols - 1)
                out.write("\x1b[H" + text.replace("\n", "\x1b[K\n") + "\x1b[J")
            else:
                for line in state.take_lines():
                    out.write(line + "\n")
            out.flush()
            if end is not None and time.monotonic() >= end:
                break
            if until_closed is not None and state.closed_trucks >= until_closed:
                break
            stop.wait(refresh_s)
    finally:
        if tty:
            out.write("\x1b[?25h")
            out.flush()
        else:
            for line in state.take_lines():
                out.write(line + "\n")
            out.flush()


def watch_link(state: CabState, client: CabClient, where: str, stop: threading.Event,
               check_s: float = 1.0) -> None:
    """Ask the open session every ``check_s`` whether it still reaches anything, until
    ``stop``. A router that goes away (restarted, switched off) leaves the session open
    and every shovel silent at once: the screen says it is its own link, not the
    shovels' (``state.set_link("down", ...)``), and its log says it once each way."""
    from shoveld.daemon.publisher import Reach

    reach = Reach(where, "zenoh: this screen cannot reach %s", log)
    while not stop.wait(check_s):
        was_lost = reach.since is not None
        lost_s = reach.update(client.reaches() != 0, time.monotonic())
        if lost_s is not None:
            state.set_link("down", f"this screen cannot reach {where} for {lost_s:.0f} s: "
                           "no shovel's messages can come")
        elif was_lost:
            state.set_link("up", where)


def connect_waiting(state: CabState, args: argparse.Namespace, tls: TlsConfig | None,
                    retry_s: float = 2.0) -> CabClient | None:
    """Open the Zenoh session, waiting for the daemon or the router to come up: a cab
    switched on before them says what it waits for and keeps trying (None: --duration
    ran out first, or Ctrl-C)."""
    where = ", ".join(args.connect or ["tcp/127.0.0.1:7447"])
    end = None if args.duration is None else time.monotonic() + args.duration
    said = False
    while True:
        try:
            return CabClient(state, args.connect or ["tcp/127.0.0.1:7447"], args.mode,
                             args.shovel, args.prefix, tls)
        except Exception:  # noqa: BLE001 - zenoh.ZError: nothing answers there yet
            if not said:
                print(f"waiting for Zenoh at {where} (the shovel's daemon or the site router "
                      f"is not answering yet); trying every {retry_s:g} s, Ctrl-C to stop",
                      file=sys.stderr, flush=True)
                said = True
        if end is not None and time.monotonic() >= end:
            return None
        try:
            time.sleep(retry_s)
        except KeyboardInterrupt:
            return None


def run(args: argparse.Namespace) -> int:
    # an option of the other view was ignored without a word (a --listen without --web
    # drew in the terminal, and no page was served where the kiosk looked for it)
    if args.web:
        other = [o for o, v in (("--lines", args.lines),
                                ("--until-closed-trucks", args.until_closed_trucks)) if v]
        if other:
            raise CliError(f"{', '.join(other)}: for the cab in the terminal, not the page "
                           "(--web)")
        return run_web(args, "")
    if args.listen is not None:
        raise CliError("--listen is the address of the cab page: add --web (the cab in the "
                       "terminal serves no page)")
    state = CabState()
    tls = tls_from_args(args)
    client = connect_waiting(state, args, tls)
    if client is None:
        return 0
    state.set_link("up")
    stop = threading.Event()
    watch = threading.Thread(target=watch_link, args=(
        state, client, ", ".join(args.connect or ["tcp/127.0.0.1:7447"]), stop),
        name="cab-link", daemon=True)
    watch.start()
    try:
        show(state, sys.stdout, sys.stdout.isatty() and not args.lines, stop, args.duration,
             args.until_closed_trucks)
    except KeyboardInterrupt:
        pass
    finally:
        stop.set()
        watch.join(5)
        client.close()
    return 0
