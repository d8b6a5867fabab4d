"""The pass log: SQLite in WAL mode under the state directory.

A finished pass is committed (``synchronous=FULL``: on disk, not only in the OS
cache) before anything is published about it, so a subscriber never sees a pass
the shovel could forget. SQLite's journal makes every write all-or-nothing, which
is what lets the daemon be killed at any instant (``SIGKILL`` mid-write included)
and come back with every finished pass and the current truck. Readers (``shoveld
passes``) work concurrently thanks to WAL.
"""

from __future__ import annotations

import logging
import sqlite3
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from shoveld.payload.misfit import MISFIT_RECENT

log = logging.getLogger(__name__)

SCHEMA_VERSION = 4
"""2 (2026-11-29): the passes' ``misfit``; a version-1 log gains the column when the
daemon opens it (its passes keep NULL there), in one transaction. 3 (2026-11-29, the
thirty-first session): the table ``empties``, the empty dipper weighed on each return;
an older log gains it (empty) when the daemon opens it. 4 (2026-11-30, the thirty-third
session): the table ``calibrations``, each params' note from the pass they were first
used on (``PassLog.note_calibration``), where the note of the last params only was kept
in ``meta``; an older log gains it (empty) the same way."""
DB_NAME = "passes.sqlite"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS passes (
    pass INTEGER PRIMARY KEY,
    truck INTEGER NOT NULL,
    shovel TEXT NOT NULL,
    start_unix REAL NOT NULL,
    end_unix REAL NOT NULL,
    start_s REAL NOT NULL,
    end_s REAL NOT NULL,
    payload_kg REAL,
    std_kg REAL,
    samples INTEGER NOT NULL,
    valid INTEGER NOT NULL,
    reason TEXT NOT NULL DEFAULT '',
    written_unix REAL NOT NULL,
    misfit REAL
);
CREATE INDEX IF NOT EXISTS passes_end ON passes(end_unix);
CREATE TABLE IF NOT EXISTS trucks (
    truck INTEGER PRIMARY KEY,
    target_kg REAL NOT NULL,
    opened_unix REAL NOT NULL,
    closed_unix REAL
);
CREATE TABLE IF NOT EXISTS empties (
    after_pass INTEGER PRIMARY KEY,
    shovel TEXT NOT NULL,
    end_unix REAL NOT NULL,
    payload_kg REAL NOT NULL,
    std_kg REAL NOT NULL,
    samples INTEGER NOT NULL,
    median_kg REAL NOT NULL,
    beyond INTEGER NOT NULL,
    warn_kg REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS empties_end ON empties(end_unix);
CREATE TABLE IF NOT EXISTS calibrations (
    from_pass INTEGER PRIMARY KEY,
    params TEXT NOT NULL,
    note TEXT NOT NULL
);
"""


@dataclass
class Restored:
    """Where the engine picks up after a restart."""

    next_pass: int = 1
    truck: int = 1
    truck_passes: list[dict[str, Any]] = field(default_factory=list)
    last_dump_unix: float | None = None
    last_dump_boot: str | None = None
    """The last dump on the live clock, "<boot id> <monotonic s>" (see ``write_pass``)."""
    recent_misfits: list[float] = field(default_factory=list)
    """The misfits of the last passes weighed with these params (not those not weighed;
    at most ``RESTORED_MISFITS``, oldest first): health's count of passes the model did
    not fit goes on across a restart."""
    empty_checks: list[float] = field(default_factory=list)
    """The empty dipper's weights of the last returns with these params (at most
    ``RESTORED_EMPTIES``, oldest first), for the same reason."""


RESTORED_MISFITS = MISFIT_RECENT
"""As many as the engine counts."""
RESTORED_EMPTIES = 20
"""More than the engine's median takes (``EngineConfig.empty_returns``, 5 by default):
it keeps its last ones."""


def db_path(state_dir: str | Path) -> Path:
    return Path(state_dir) / DB_NAME


def connect(path: str | Path, readonly: bool = False, durable: bool = True
            ) -> sqlite3.Connection:
    """Open the pass log (WAL, FULL sync); a reader may not create it.

    ``durable=False``: no fsync at all (``synchronous = OFF``), for a pass log that is
    thrown away when the process ends (``shoveld replay`` without ``--state-dir``): the
    fsyncs of creating it, committing each pass and checkpointing at close were 40-50
    ms of a 0.6 s replay command on this machine's disk, and protect nothing there."""
    p = Path(path)
    if readonly:
        if not p.exists():
            raise FileNotFoundError(f"{p}: no pass log here (has the daemon run?)")
        # as_uri() percent-encodes the path: a '#' or '?' in a folder name would
        # otherwise end the file name and open (or create) another file
        # Read-write without create, used only to read: after a crash of the daemon, the
        # last commits are in the write-ahead log, and only a connection that may write
        # can recover its index; a read-only one reads the database without them (a
        # pass log audited after a kill missed its last pass that way). A reader without
        # write permission still opens read-only.
        uri = p.resolve().as_uri()
        try:
            con = sqlite3.connect(f"{uri}?mode=rw", uri=True, timeout=5.0,
                                  check_same_thread=False)
            con.execute("PRAGMA query_only = 1")
            con.execute("SELECT count(*) FROM sqlite_master").fetchone()
        except sqlite3.OperationalError:
            con = sqlite3.connect(f"{uri}?mode=ro", uri=True, timeout=5.0,
                                  check_same_thread=False)
        con.execute("PRAGMA busy_timeout = 5000")
        return con
    if p.parent.exists() and not p.parent.is_dir():
        raise NotADirectoryError("a file is there, not a folder")
    if not p.parent.exists():
        # owner-only whatever the umask of what starts us (a systemd unit's UMask, a
        # shell's): the pass log is the mine's production record
        p.parent.mkdir(parents=True, mode=0o700)
        p.parent.chmod(0o700)
    con = sqlite3.connect(str(p), timeout=5.0, isolation_level=None, check_same_thread=False)
    con.execute("PRAGMA busy_timeout = 5000")
    if not durable:  # before the switch to WAL, which would sync the new file
        con.execute("PRAGMA synchronous = OFF")
    mode = con.execute("PRAGMA journal_mode = WAL").fetchone()[0]
    if str(mode).lower() != "wal":
        log.warning("%s: journal_mode is %s, not WAL", p, mode)
    if durable:
        con.execute("PRAGMA synchronous = FULL")
    con.executescript("BEGIN;" + _SCHEMA + "COMMIT;")  # all tables or none, even if killed
    con.execute("INSERT OR IGNORE INTO meta(key, value) VALUES ('schema', ?)",
                (str(SCHEMA_VERSION),))
    if not _has_misfit(con):  # a version-1 log: the column and the version, or neither
        con.executescript("BEGIN IMMEDIATE; ALTER TABLE passes ADD COLUMN misfit REAL; "
                          f"UPDATE meta SET value = '{SCHEMA_VERSION}' WHERE key = 'schema'; "
                          "COMMIT;")
    # a version-2 or 3 log has its new tables from the schema above: say so in its version
    con.execute("UPDATE meta SET value = ? WHERE key = 'schema' AND CAST(value AS INTEGER) < ?",
                (str(SCHEMA_VERSION), SCHEMA_VERSION))
    return con


def _has_misfit(con: sqlite3.Connection) -> bool:
    """Whether the pass log's passes have the ``misfit`` column (schema 2)."""
    return any(r[1] == "misfit" for r in con.execute("PRAGMA table_info(passes)"))


def _row_to_pass(row: sqlite3.Row | tuple[Any, ...]) -> dict[str, Any]:
    (pass_, truck, start_s, end_s, payload, std, samples, valid, reason, misfit) = row
    return {"pass": pass_, "truck": truck, "start_s": start_s, "end_s": end_s,
            "payload_kg": payload, "std_kg": std, "samples": samples, "valid": bool(valid),
            "reason": reason, "misfit": misfit}


class PassLog:
    """Writes passes and truck closures; restores the current truck."""

    def __init__(self, path: str | Path, shovel: str, durable: bool = True) -> None:
        self.path = Path(path)
        self.shovel = shovel
        self.durable = durable
        """False: nothing synced to disk (:func:`connect`), for a throw-away pass log."""
        self.con = connect(self.path, durable=durable)
        self.writes = 0

    def close(self) -> None:
        try:
            self.con.close()
        except sqlite3.Error:
            pass

    def restore(self, params: str | None = None) -> Restored:
        """Where the engine picks up: the next pass, the open truck and its passes, the
        last dump; with ``params`` (``ModelParams.fingerprint``), the last misfits and
        empty-dipper checks made with those params. The log keeps which params it was
        written with since which pass: a start with other params starts their checks
        afresh."""
        c = self.con
        last = c.execute("SELECT max(pass) FROM passes").fetchone()[0]
        r = Restored(next_pass=(last or 0) + 1)
        row = c.execute("SELECT truck FROM trucks WHERE closed_unix IS NULL "
                        "ORDER BY truck DESC LIMIT 1").fetchone()
        max_truck = c.execute("SELECT max(truck) FROM trucks").fetchone()[0] or 0
        if row is not None and row[0] == max_truck:
            r.truck = row[0]
            rows = c.execute("SELECT pass, truck, start_s, end_s, payload_kg, std_kg, samples, "
                             "valid, reason, misfit FROM passes WHERE truck = ? ORDER BY pass",
                             (r.truck,)).fetchall()
            r.truck_passes = [_row_to_pass(x) for x in rows]
        else:
            r.truck = max_truck + 1
        end = c.execute("SELECT end_unix FROM passes ORDER BY pass DESC LIMIT 1").fetchone()
        r.last_dump_unix = end[0] if end else None
        boot = c.execute("SELECT value FROM meta WHERE key = 'last_dump_boot'").fetchone()
        r.last_dump_boot = boot[0] if boot and end else None
        if params is not None:
            self._restore_checks(r, params)
        return r

    def _restore_checks(self, r: Restored, params: str) -> None:
        c = self.con
        row = c.execute("SELECT value FROM meta WHERE key = 'params'").fetchone()
        since = c.execute("SELECT value FROM meta WHERE key = 'params_from_pass'").fetchone()
        if row is None or row[0] != params or since is None or not str(since[0]).isdigit():
            c.execute("BEGIN IMMEDIATE")  # these params from the next pass on, both or none
            try:
                c.execute("INSERT OR REPLACE INTO meta(key, value) VALUES ('params', ?)",
                          (params,))
                c.execute("INSERT OR REPLACE INTO meta(key, value) "
                          "VALUES ('params_from_pass', ?)", (str(r.next_pass),))
                c.execute("COMMIT")
            except BaseException:
                if c.in_transaction:
                    c.execute("ROLLBACK")
                raise
            return
        first = int(since[0])
        r.recent_misfits = [m for (m,) in reversed(c.execute(
            "SELECT misfit FROM passes WHERE pass >= ? AND misfit IS NOT NULL AND valid = 1 "
            "ORDER BY pass DESC LIMIT ?", (first, RESTORED_MISFITS)).fetchall())]
        r.empty_checks = [kg for (kg,) in reversed(c.execute(
            "SELECT payload_kg FROM empties WHERE after_pass >= ? "
            "ORDER BY after_pass DESC LIMIT ?", (first, RESTORED_EMPTIES)).fetchall())]

    def note_calibration(self, note: str) -> None:
        """What the daemon's params say of their own calibration ("" for nothing: the
        ratio of ``calibrate --verified`` below its level, or none), kept with their
        fingerprint and the pass they were first used on (``restore`` recorded both), so
        that the shift report says it of the passes weighed with them, whatever params
        came after."""
        c = self.con
        meta = dict(c.execute("SELECT key, value FROM meta WHERE key IN "
                              "('params', 'params_from_pass')").fetchall())
        first = str(meta.get("params_from_pass", ""))
        if "params" not in meta or not first.isdigit():
            return  # no params recorded by restore: no pass to say it of
        c.execute("INSERT OR REPLACE INTO calibrations(from_pass, params, note) "
                  "VALUES (?, ?, ?)", (int(first), meta["params"], note))

    def write_pass(self, p: dict[str, Any], start_unix: float, end_unix: float,
                   target_kg: float, boot_stamp: str | None = None) -> bool:
        """Commit one finished pass (and open its truck); False if it was already there.

        ``boot_stamp``: the dump on the live clock, kept in the same transaction so that a
        restart measures the truck gap without trusting wall time (NTP may step it)."""
        c = self.con
        now = time.time()
        try:
            c.execute("BEGIN IMMEDIATE")
            c.execute("INSERT OR IGNORE INTO trucks(truck, target_kg, opened_unix) "
                      "VALUES (?, ?, ?)", (p["truck"], target_kg, start_unix))
            c.execute("INSERT INTO passes(pass, truck, shovel, start_unix, end_unix, start_s, "
                      "end_s, payload_kg, std_kg, samples, valid, reason, written_unix, "
                      "misfit) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                      (p["pass"], p["truck"], self.shovel, start_unix, end_unix, p["start_s"],
                       p["end_s"], p["payload_kg"], p["std_kg"], p["samples"],
                       int(bool(p["valid"])), p.get("reason", ""), now, p.get("misfit")))
            if boot_stamp is not None:
                c.execute("INSERT OR REPLACE INTO meta(key, value) VALUES ('last_dump_boot', ?)",
                          (boot_stamp,))
            else:
                c.execute("DELETE FROM meta WHERE key = 'last_dump_boot'")
            c.execute("COMMIT")
        except sqlite3.IntegrityError:
            c.execute("ROLLBACK")
            log.error("pass %s is already in the pass log; not written again", p["pass"])
            return False
        except BaseException:
            if c.in_transaction:
                c.execute("ROLLBACK")
            raise
        self.writes += 1
        return True

    def write_empty(self, e: dict[str, Any], end_unix: float, warn_kg: float,
                    beyond: bool) -> bool:
        """Commit one return's empty-dipper check (``EmptyCheck.as_dict``), with the level
        the daemon held it to and whether the median was beyond it then; False if the
        check after that pass is there already."""
        c = self.con
        cur = c.execute("INSERT OR IGNORE INTO empties(after_pass, shovel, end_unix, payload_kg, "
                        "std_kg, samples, median_kg, beyond, warn_kg) "
                        "VALUES (?,?,?,?,?,?,?,?,?)",
                        (e["after_pass"], self.shovel, end_unix, e["payload_kg"], e["std_kg"],
                         e["samples"], e["median_kg"], int(beyond), warn_kg))
        return cur.rowcount == 1

    def close_truck(self, truck: int, target_kg: float, closed_unix: float) -> None:
        c = self.con
        c.execute("BEGIN IMMEDIATE")
        try:
            c.execute("INSERT OR IGNORE INTO trucks(truck, target_kg, opened_unix) "
                      "VALUES (?, ?, ?)", (truck, target_kg, closed_unix))
            c.execute("UPDATE trucks SET closed_unix = ? WHERE truck = ? AND closed_unix IS NULL",
                      (closed_unix, truck))
            c.execute("COMMIT")
        except BaseException:
            if c.in_transaction:
                c.execute("ROLLBACK")
            raise

    def closed_trucks_misfit_high(self, since_unix: float, warn: float) -> int:
        """Weighed passes of the trucks closed since ``since_unix`` whose misfit was above
        ``warn`` (the passes the cab marked): the shift's count the office shows."""
        return int(self.con.execute(
            "SELECT count(*) FROM passes p JOIN trucks t ON p.truck = t.truck "
            "WHERE t.closed_unix IS NOT NULL AND t.closed_unix >= ? AND p.valid "
            "AND p.misfit > ?",
            (since_unix, warn)).fetchone()[0])

    def closed_truck_totals(self, since_unix: float) -> list[ClosedTruck]:
        """The trucks closed since ``since_unix``, oldest first, with their weighed totals
        and how many of their passes were not weighed."""
        rows = self.con.execute(
            "SELECT t.truck, coalesce(sum(CASE WHEN p.valid THEN p.payload_kg END), 0), "
            "t.target_kg, count(p.pass), count(p.pass) - count(CASE WHEN p.valid THEN 1 END) "
            "FROM trucks t LEFT JOIN passes p ON p.truck = t.truck "
            "WHERE t.closed_unix IS NOT NULL AND t.closed_unix >= ? GROUP BY t.truck "
            "ORDER BY t.truck", (since_unix,)).fetchall()
        return [ClosedTruck(int(a), float(b), float(c), int(d), int(e))
                for a, b, c, d, e in rows]


class ClosedTruck(NamedTuple):
    """A closed truck as the pass log sums it (:meth:`PassLog.closed_truck_totals`)."""

    truck: int
    total_kg: float
    """Its weighed passes' sum (a lower bound of its load when ``not_weighed``)."""
    target_kg: float
    passes: int
    not_weighed: int


def _window(since_unix: float | None, until_unix: float | None) -> tuple[float, float]:
    """A reader's [since, until) as query bounds (None: open on that side)."""
    return (since_unix if since_unix is not None else -1e18,
            until_unix if until_unix is not None else 1e18)


PASS_COLUMNS = ("pass", "truck", "shovel", "start", "end", "payload_kg", "std_kg", "samples",
                "valid", "reason", "misfit")


def read_passes(path: str | Path, since_unix: float | None = None,
                until_unix: float | None = None) -> list[dict[str, Any]]:
    """Passes that ended in [since, until), oldest first (for shift reports)."""
    con = connect(path, readonly=True)
    try:
        # a version-1 log that no daemon of schema 2 has opened yet: no misfit there
        misfit = "misfit" if _has_misfit(con) else "NULL"
        q = ("SELECT pass, truck, shovel, start_unix, end_unix, payload_kg, std_kg, samples, "
             f"valid, reason, {misfit} FROM passes WHERE end_unix >= ? AND end_unix < ? "
             "ORDER BY pass")
        rows = con.execute(q, _window(since_unix, until_unix)).fetchall()
        trucks = {int(t): (target, closed) for t, target, closed in con.execute(
            "SELECT truck, target_kg, closed_unix FROM trucks")}
    finally:
        con.close()
    out = []
    for r in rows:
        d = dict(zip(PASS_COLUMNS, r, strict=True))
        d["valid"] = bool(d["valid"])
        target, closed = trucks.get(int(d["truck"]), (None, None))
        d["truck_target_kg"] = target
        d["truck_closed"] = closed is not None
        out.append(d)
    return out


EMPTY_COLUMNS = ("after_pass", "shovel", "end", "payload_kg", "std_kg", "samples",
                 "median_kg", "beyond", "warn_kg")


def read_empties(path: str | Path, since_unix: float | None = None,
                 until_unix: float | None = None) -> list[dict[str, Any]] | None:
    """The empty-dipper checks that ended in [since, until), oldest first; None for a pass
    log that records none (written before schema 3, and not opened by a daemon since)."""
    con = connect(path, readonly=True)
    try:
        if not con.execute("SELECT 1 FROM sqlite_master WHERE name = 'empties'").fetchone():
            return None
        rows = con.execute(
            "SELECT after_pass, shovel, end_unix, payload_kg, std_kg, samples, median_kg, "
            "beyond, warn_kg FROM empties WHERE end_unix >= ? AND end_unix < ? "
            "ORDER BY end_unix", _window(since_unix, until_unix)).fetchall()
    finally:
        con.close()
    out = []
    for r in rows:
        d = dict(zip(EMPTY_COLUMNS, r, strict=True))
        d["beyond"] = bool(d["beyond"])
        out.append(d)
    return out


def read_calibrations(path: str | Path) -> list[tuple[str, int, int | None]]:
    """What each params the daemon ran with said of their own calibration
    (``PassLog.note_calibration``), with the first and the last pass weighed with them
    (None: to the end), oldest first; only those that said something. Empty for a log
    written before the thirty-third session's schema 4."""
    con = connect(path, readonly=True)
    try:
        try:
            rows = con.execute("SELECT from_pass, note FROM calibrations "
                               "ORDER BY from_pass").fetchall()
        except sqlite3.OperationalError:  # no such table: an older log, not reopened since
            return []
    finally:
        con.close()
    out: list[tuple[str, int, int | None]] = []
    for k, (first, note) in enumerate(rows):
        if not note:
            continue  # nothing to say
        last = rows[k + 1][0] - 1 if k + 1 < len(rows) else None
        out.append((str(note), first, last))
    return out


@dataclass
class Audit:
    """What ``audit_log`` found: a pass log is sound when ``problems`` is empty."""

    passes: list[int] = field(default_factory=list)
    open_truck: int | None = None
    open_truck_passes: list[int] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def audit_log(path: str | Path) -> Audit:
    """Check a pass log as a crash could have left it: SQLite's integrity check, pass
    numbers 1..n with no gap, truck numbers with no gap, at most one open truck (the
    newest), each pass complete (a valid one has its payload, an invalid one none)."""
    a = Audit()
    con = connect(path, readonly=True)
    try:
        ok = con.execute("PRAGMA integrity_check").fetchone()[0]
        if ok != "ok":
            a.problems.append(f"integrity_check: {ok}")
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master")}
        if "passes" not in tables:
            # killed after the file was created, before the schema was committed: nothing
            # had been written, and a restart creates the schema
            if "trucks" in tables:
                a.problems.append("a trucks table without a passes table")
            return a
        a.passes = [r[0] for r in con.execute("SELECT pass FROM passes ORDER BY pass")]
        if a.passes != list(range(1, len(a.passes) + 1)):
            a.problems.append(f"pass numbers are not 1..{len(a.passes)}")
        for n, truck, kg, std, valid, samples in con.execute(
                "SELECT pass, truck, payload_kg, std_kg, valid, samples FROM passes"):
            if truck < 1 or samples <= 0 or (
                    (kg is None or std is None) if valid else kg is not None):
                a.problems.append(f"pass {n} is incomplete")
        trucks = con.execute("SELECT truck, closed_unix FROM trucks ORDER BY truck").fetchall()
        numbers = [t for t, _ in trucks]
        if numbers and numbers != list(range(numbers[0], numbers[0] + len(numbers))):
            a.problems.append(f"truck numbers have a gap: {numbers}")
        open_ = [t for t, closed in trucks if closed is None]
        if len(open_) > 1 or (open_ and open_[0] != numbers[-1]):
            a.problems.append(f"open trucks {open_} (at most the newest may be open)")
        a.open_truck = open_[-1] if open_ else None
        if "empties" in tables:
            # a return's check is queued after its pass's commit: never before it
            orphans = [r[0] for r in con.execute(
                "SELECT after_pass FROM empties WHERE after_pass NOT IN "
                "(SELECT pass FROM passes) ORDER BY after_pass")]
            if orphans:
                a.problems.append(f"empty-dipper checks after passes not in the log: "
                                  f"{orphans}")
        if a.open_truck is not None:
            a.open_truck_passes = [r[0] for r in con.execute(
                "SELECT pass FROM passes WHERE truck = ? ORDER BY pass", (a.open_truck,))]
    finally:
        con.close()
    return a
