"""The pass log: WAL, durable writes, restore of the current truck, export."""

from __future__ import annotations

import os
import sqlite3
import stat
from pathlib import Path
from typing import Any

import pytest

from shoveld.cli import main
from shoveld.cli.passes import parse_when
from shoveld.daemon.persist import (
    SCHEMA_VERSION,
    PassLog,
    audit_log,
    db_path,
    read_empties,
    read_passes,
)


def p(n: int, truck: int, kg: float = 30000.0, valid: bool = True) -> dict[str, Any]:
    return {"pass": n, "truck": truck, "start_s": 10.0 * n, "end_s": 10.0 * n + 8,
            "payload_kg": kg if valid else None, "std_kg": 200.0 if valid else None,
            "samples": 300 if valid else 3, "valid": valid,
            "reason": "" if valid else "only 3 valid samples"}


T0 = 1_790_000_000.0


def test_wal_and_restore_of_the_open_truck(tmp_path: Path) -> None:
    log = PassLog(db_path(tmp_path), "s1")
    assert log.con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert log.con.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
    r = log.restore()
    assert (r.next_pass, r.truck, r.truck_passes, r.last_dump_unix) == (1, 1, [], None)
    log.write_pass(p(1, 1), T0, T0 + 8, 136000.0)
    log.write_pass(p(2, 1, valid=False), T0 + 10, T0 + 18, 136000.0)
    log.close()
    r = PassLog(db_path(tmp_path), "s1").restore()
    assert r.next_pass == 3 and r.truck == 1 and r.last_dump_unix == T0 + 18
    assert [x["pass"] for x in r.truck_passes] == [1, 2]
    assert r.truck_passes[1]["valid"] is False and r.truck_passes[1]["payload_kg"] is None


def test_closed_truck_starts_the_next_one(tmp_path: Path) -> None:
    log = PassLog(db_path(tmp_path), "s1")
    for n in (1, 2):
        log.write_pass(p(n, 1), T0 + n, T0 + n + 0.5, 62000.0)
    log.close_truck(1, 62000.0, T0 + 5)
    r = log.restore()
    assert r.next_pass == 3 and r.truck == 2 and r.truck_passes == []
    assert log.closed_truck_totals(T0) == [(1, 60000.0, 62000.0, 2, 0)]
    log.write_pass(p(3, 2), T0 + 30, T0 + 31, 62000.0)
    r = log.restore()
    assert r.truck == 2 and [x["pass"] for x in r.truck_passes] == [3]


def test_a_pass_is_never_written_twice(tmp_path: Path) -> None:
    log = PassLog(db_path(tmp_path), "s1")
    assert log.write_pass(p(1, 1), T0, T0 + 1, 62000.0)
    assert not log.write_pass(p(1, 1, kg=1.0), T0, T0 + 1, 62000.0)
    rows = read_passes(db_path(tmp_path))
    assert len(rows) == 1 and rows[0]["payload_kg"] == 30000.0
    assert not log.con.in_transaction


def test_closed_trucks_count_their_passes_not_weighed(tmp_path: Path) -> None:
    """The shift's closed trucks as the daemon sums them for the 10/10/20 rule: a truck
    with a pass not weighed carries the count, and its total is the weighed passes'."""
    log = PassLog(db_path(tmp_path), "s1")
    log.write_pass(p(1, 1), T0, T0 + 1, 62000.0)
    log.write_pass(p(2, 1, valid=False), T0 + 2, T0 + 3, 62000.0)
    log.close_truck(1, 62000.0, T0 + 5)
    log.close_truck(2, 62000.0, T0 + 6)  # sent off with no pass: nothing not weighed
    got = log.closed_truck_totals(T0)
    assert got == [(1, 30000.0, 62000.0, 2, 1), (2, 0.0, 62000.0, 0, 0)]
    assert got[0].not_weighed == 1 and got[0].total_kg == 30000.0


def test_readers_work_while_the_writer_holds_the_log(tmp_path: Path) -> None:
    log = PassLog(db_path(tmp_path), "s1")
    log.write_pass(p(1, 1), T0, T0 + 1, 62000.0)
    log.con.execute("BEGIN IMMEDIATE")
    log.con.execute("INSERT INTO meta(key, value) VALUES ('x', 'y')")
    assert len(read_passes(db_path(tmp_path))) == 1  # WAL: readers do not wait
    log.con.execute("ROLLBACK")
    with pytest.raises(FileNotFoundError):
        read_passes(tmp_path / "nope.sqlite")


def test_passes_export(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = PassLog(db_path(tmp_path), "s7")
    misfits = {1: 0.81, 3: 18.25}  # pass 2 as a daemon before 2026-11-29 wrote it: none
    for n, (truck, kg) in enumerate([(1, 30000.0), (1, 31000.0), (2, 40000.0)], start=1):
        log.write_pass({**p(n, truck, kg), "misfit": misfits.get(n)}, T0 + 100 * n,
                       T0 + 100 * n + 20, 62000.0)
    log.close_truck(1, 62000.0, T0 + 250)
    log.write_pass(p(4, 2, valid=False), T0 + 400, T0 + 420, 62000.0)
    log.close()
    assert main(["passes", "--state-dir", str(tmp_path), "--csv"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "pass,truck,shovel,start,end,payload_kg,std_kg,samples,valid,reason,misfit"
    assert len(out) == 5 and out[1].startswith("1,1,s7,") and ",30000.0,200.0,300,1," in out[1]
    assert out[1].endswith(",1,,0.81") and out[2].endswith(",1,,") and out[3].endswith(",18.25")
    assert out[4].endswith(",,,3,0,only 3 valid samples,")
    assert main(["passes", "--db", str(db_path(tmp_path)), "--since", str(T0 + 250)]) == 0
    text = capsys.readouterr().out
    assert "pass     3" in text and "pass     1" not in text
    # a pass the model did not fit says so on its line, one it fitted says nothing
    line3 = next(ln for ln in text.splitlines() if ln.startswith("pass     3"))
    assert line3.endswith("misfit 18.2: the model does not fit this pass")
    assert "misfit" not in next(ln for ln in text.splitlines() if ln.startswith("pass     4"))
    # pass 4 was not weighed: the open truck's 40 t is its load's lower bound, not "under"
    assert "truck    2: 2 passes (1 not weighed), at least 40000 kg of 62000 kg " \
           "(64.5 %), incomplete (open)" in text
    assert main(["passes", "--state-dir", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "10/10/20 over 1 closed truck:" in text  # not "1 closed trucks"
    assert main(["passes", "--state-dir", str(tmp_path / "empty")]) == 2
    assert "no pass log" in capsys.readouterr().err


def test_parse_when() -> None:
    now = 1_800_000_000.0
    assert parse_when("12h", now) == now - 12 * 3600
    assert parse_when("30m", now) == now - 1800
    assert parse_when("1790000000", now) == 1_790_000_000.0
    assert parse_when("2026-11-21T18:00:00+00:00", now) == 1795284000.0
    with pytest.raises(Exception, match="cannot read time"):
        parse_when("yesterday-ish", now)
    # "Unix seconds" said with what they must look like: "0" was refused under that name
    with pytest.raises(Exception, match="or Unix seconds of 9 digits or more"):
        parse_when("0", now)
    # today / yesterday: local midnight, a day apart, the first not after now
    today, yesterday = parse_when("today", now), parse_when("yesterday", now)
    assert 0 <= now - today < 86400 and 82800 <= today - yesterday <= 90000
    assert parse_when("2026-11-21", now) == parse_when("2026-11-21T00:00", now)
    # a time the output's dates cannot hold (a traceback at the listing, until 2026-11-30)
    for far in ("99999999999999", "0001-01-01", "9999-12-31T23:59+00:00", "99999999d"):
        with pytest.raises(Exception, match=r"outside 1970-01-01 \.\. 9999-12-30"):
            parse_when(far, now)
    assert parse_when("9999-12-29T00:00+00:00", now) == 253402041600.0


@pytest.mark.parametrize("when", ["99999999999999", "0001-01-01"])
def test_a_time_out_of_the_calendar_is_one_line(when: str, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    from shoveld.cli import main

    for cmd in (["passes"], ["report", "--out", str(tmp_path / "r")]):
        assert main([*cmd, "--db", str(tmp_path / "none.sqlite"), "--since", when]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "outside 1970-01-01" in err[0], err


def test_commands_find_a_local_config_before_the_installed_one(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
        ) -> None:
    from shoveld.cli import main
    from shoveld.paths import DEFAULT_CONFIG, find_config

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("SHOVELD_CONFIG", raising=False)
    assert find_config() == DEFAULT_CONFIG
    (tmp_path / "shoveld.toml").write_text("[shovel]\nid = 1\n")
    assert find_config() == "shoveld.toml"
    assert main(["check-config"]) == 2  # it reads the local file, and names it
    assert "shoveld.toml" in capsys.readouterr().err
    monkeypatch.setenv("SHOVELD_CONFIG", str(tmp_path / "other.toml"))
    assert find_config() == str(tmp_path / "other.toml")


def test_database_is_plain_sqlite(tmp_path: Path) -> None:
    PassLog(db_path(tmp_path), "s1").write_pass(p(1, 1), T0, T0 + 1, 62000.0)
    con = sqlite3.connect(db_path(tmp_path))
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert con.execute("SELECT count(*) FROM passes").fetchone()[0] == 1


def test_the_boot_stamp_goes_with_the_last_pass(tmp_path: Path) -> None:
    """Written in the pass's transaction; a pass without one (a simulated clock) clears
    it, so an old stamp is never taken for a newer dump."""
    log = PassLog(db_path(tmp_path), "s1")
    log.write_pass(p(1, 1), T0, T0 + 8, 62000.0, "boot-a 1234.5")
    assert log.restore().last_dump_boot == "boot-a 1234.5"
    log.write_pass(p(2, 1), T0 + 10, T0 + 18, 62000.0)
    assert log.restore().last_dump_boot is None
    assert log.restore().last_dump_unix == T0 + 18


@pytest.mark.parametrize("folder", ["shift#2", "what?now", "50%"])
def test_reader_opens_the_log_whatever_the_folder_is_called(tmp_path: Path,
                                                            folder: str) -> None:
    # A '#' or '?' in an unescaped URI ends the file name: the reader would open (or
    # fail on) another file than the daemon writes.
    state = tmp_path / folder
    log = PassLog(db_path(state), "s1")
    log.write_pass(p(1, 1), T0, T0 + 8, 136000.0)
    log.close()
    assert [r["pass"] for r in read_passes(db_path(state))] == [1]
    assert sorted(x.name for x in tmp_path.iterdir()) == [folder]  # nothing else created


def test_a_new_state_folder_is_owner_only_whatever_the_umask(tmp_path: Path) -> None:
    old = os.umask(0o002)
    try:
        PassLog(db_path(tmp_path / "state"), "s1").close()
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "state").stat().st_mode) == 0o700


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    from shoveld.cli import main

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith("shoveld 0.")


def test_help_shows_defaults(capsys: pytest.CaptureFixture[str]) -> None:
    from shoveld.cli import main

    with pytest.raises(SystemExit):
        main(["sim", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "passes to dig (cycles) (default: 12)" in out and "(default: None)" not in out
    assert "--out FILE" in out and "required" in out


def test_a_throwaway_pass_log_keeps_wal_and_restores_without_syncing(tmp_path: Path) -> None:
    """``durable=False`` changes only the sync: WAL, schema, writes and restore as live."""
    log = PassLog(db_path(tmp_path), "s1", durable=False)
    assert log.con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert log.con.execute("PRAGMA synchronous").fetchone()[0] == 0  # OFF
    log.write_pass(p(1, 1), T0, T0 + 8, 136000.0)
    log.write_pass(p(2, 1), T0 + 10, T0 + 18, 136000.0)
    log.close()
    again = PassLog(db_path(tmp_path), "s1")  # the default: durable
    assert again.con.execute("PRAGMA synchronous").fetchone()[0] == 2
    r = again.restore()
    assert r.next_pass == 3 and [x["pass"] for x in r.truck_passes] == [1, 2]


V1_SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE passes (
    pass INTEGER PRIMARY KEY, truck INTEGER NOT NULL, shovel TEXT NOT NULL,
    start_unix REAL NOT NULL, end_unix REAL NOT NULL, start_s REAL NOT NULL,
    end_s REAL NOT NULL, payload_kg REAL, std_kg REAL, samples INTEGER NOT NULL,
    valid INTEGER NOT NULL, reason TEXT NOT NULL DEFAULT '', written_unix REAL NOT NULL);
CREATE TABLE trucks (truck INTEGER PRIMARY KEY, target_kg REAL NOT NULL,
    opened_unix REAL NOT NULL, closed_unix REAL);
INSERT INTO meta VALUES ('schema', '1');
INSERT INTO trucks VALUES (1, 62000.0, 1790000000.0, NULL);
INSERT INTO passes VALUES (1, 1, 's1', 1790000000.0, 1790000008.0, 0.0, 8.0, 30000.0,
    200.0, 300, 1, '', 1790000009.0);
"""


def test_a_pass_log_of_schema_1_is_read_as_it_is_and_gains_the_misfit_when_the_daemon_opens_it(
        tmp_path: Path) -> None:
    path = db_path(tmp_path)
    con = sqlite3.connect(path)
    con.executescript(V1_SCHEMA)
    con.close()
    # a reader does not change the log: its passes have no misfit
    rows = read_passes(path)
    assert [(r["pass"], r["payload_kg"], r["misfit"]) for r in rows] == [(1, 30000.0, None)]
    cols = [r[1] for r in sqlite3.connect(path).execute("PRAGMA table_info(passes)")]
    assert "misfit" not in cols
    assert read_empties(path) is None  # no empty-dipper checks recorded, and none made up
    # the daemon's pass log adds the column, keeps the pass and its truck
    log = PassLog(path, "s1")
    r = log.restore()
    assert r.next_pass == 2 and r.truck == 1
    assert [(x["pass"], x["payload_kg"], x["misfit"]) for x in r.truck_passes] == [
        (1, 30000.0, None)]
    assert log.con.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()[0] == (
        str(SCHEMA_VERSION))
    assert read_empties(path) == []
    assert log.write_pass({**p(2, 1), "misfit": 0.77}, T0 + 20, T0 + 28, 62000.0)
    log.close()
    assert [(r["pass"], r["misfit"]) for r in read_passes(path)] == [(1, None), (2, 0.77)]
    assert PassLog(path, "s1").restore().next_pass == 3  # opened again: nothing to add


def test_the_empty_dipper_checks_are_kept_with_the_level_they_were_held_to(
        tmp_path: Path) -> None:
    """Each return's check is committed once (the pass it followed is its key), with the
    daemon's level and its verdict then; a log of schema 2 gains the table, empty, and
    its version, when the daemon opens it, and a reader of it before then gets None."""
    path = db_path(tmp_path)
    log = PassLog(path, "s1")
    for n in (1, 2, 3):
        assert log.write_pass(p(n, 1), T0 + 30 * n, T0 + 30 * n + 8, 62000.0)
    checks = [(1, 120.4, 120.4, False), (2, 1650.2, 885.3, False), (3, 1702.9, 1650.2, True)]
    for after, kg, med, beyond in checks:
        e = {"after_pass": after, "end_s": 30.0 * after + 14, "payload_kg": kg, "std_kg": 95.0,
             "samples": 100, "median_kg": med}
        assert log.write_empty(e, T0 + 30 * after + 14, 500.0, beyond)
    assert not log.write_empty({**e, "payload_kg": 0.0}, T0 + 200, 500.0, False)  # once
    log.close()
    got = read_empties(path)
    assert got is not None
    assert [(e["after_pass"], e["payload_kg"], e["median_kg"], e["beyond"], e["warn_kg"],
             e["shovel"]) for e in got] == [(a, kg, med, b, 500.0, "s1")
                                           for a, kg, med, b in checks]
    assert [e["after_pass"] for e in read_empties(path, T0 + 70, T0 + 90) or []] == [2]
    assert not audit_log(path).problems
    con = sqlite3.connect(path)  # a check whose pass is not there: the audit names it
    con.execute("INSERT INTO empties VALUES (9, 's1', 0, 1, 1, 1, 1, 0, 500)")
    con.commit()
    con.close()
    assert audit_log(path).problems == [
        "empty-dipper checks after passes not in the log: [9]"]
    # a log of schema 2: no such table, read as it is, then opened by a daemon
    con = sqlite3.connect(path)
    con.executescript("DROP TABLE empties; UPDATE meta SET value = '2' WHERE key = 'schema';")
    con.close()
    assert read_empties(path) is None
    log = PassLog(path, "s1")
    assert log.con.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()[0] == (
        str(SCHEMA_VERSION))
    assert log.restore().next_pass == 4
    log.close()
    assert read_empties(path) == []


def test_the_shift_counts_the_weighed_passes_of_closed_trucks_above_the_level(
        tmp_path: Path) -> None:
    log = PassLog(db_path(tmp_path), "s1")
    fits = [(1, 1, True, 0.8), (2, 1, True, 4.2), (3, 1, False, 50.0), (4, 2, True, 9.9),
            (5, 3, True, 7.0)]
    for n, truck, valid, m in fits:
        log.write_pass({**p(n, truck, valid=valid), "misfit": m}, T0 + 10 * n,
                       T0 + 10 * n + 8, 62000.0)
    log.close_truck(1, 62000.0, T0 + 30)
    log.close_truck(2, 62000.0, T0 + 45)
    # pass 3 was not weighed, truck 3 is open: truck 1's pass 2 and truck 2's pass 4
    assert log.closed_trucks_misfit_high(T0, 3.0) == 2
    assert log.closed_trucks_misfit_high(T0 + 40, 3.0) == 1  # truck 1 closed before
    assert log.closed_trucks_misfit_high(T0, 5.0) == 1
    log.close()


def test_restore_carries_on_the_checks_of_the_same_params_only(tmp_path: Path) -> None:
    """A restart gives back the last misfits (at most 10) and empty-dipper checks made
    with the same params, oldest first; a start with other params gets none, and from
    then on only those made with them."""
    path = db_path(tmp_path)

    def run(params: str, passes: range) -> None:
        log = PassLog(path, "s1")
        log.restore(params)
        for n in passes:
            assert log.write_pass({**p(n, 1), "misfit": 0.5 + n}, T0 + 30 * n,
                                  T0 + 30 * n + 8, 62000.0)
            log.write_empty({"after_pass": n, "end_s": 30.0 * n + 14,
                             "payload_kg": 100.0 * n, "std_kg": 95.0, "samples": 100,
                             "median_kg": 0.0}, T0 + 30 * n + 14, 500.0, False)
        log.close()

    run("calib-a", range(1, 13))
    r = PassLog(path, "s1").restore("calib-a")
    assert r.recent_misfits == [0.5 + n for n in range(3, 13)]  # the last 10
    assert r.empty_checks == [100.0 * n for n in range(1, 13)]
    assert r.next_pass == 13
    run("calib-b", range(13, 15))  # recalibrated: a start with other params
    r = PassLog(path, "s1").restore("calib-b")
    assert r.recent_misfits == [13.5, 14.5] and r.empty_checks == [1300.0, 1400.0]
    # the first start with other params has nothing to carry on, and says so by the
    # empty lists; a reader without params asks for none
    r = PassLog(path, "s1").restore("calib-c")
    assert (r.recent_misfits, r.empty_checks) == ([], [])
    r = PassLog(path, "s1").restore()
    assert (r.recent_misfits, r.empty_checks, r.next_pass) == ([], [], 15)
    assert not audit_log(path).problems


def test_restore_carries_on_the_misfits_of_the_passes_weighed_only(tmp_path: Path) -> None:
    """A pass not weighed (a laser that changed target, a crowd in doubt) says its own
    cause: its misfit is not given back to health's count of passes the model did not
    fit, as the engine does not count it either."""
    path = db_path(tmp_path)
    log = PassLog(path, "s1")
    log.restore("calib-a")
    for n in (1, 2):
        assert log.write_pass({**p(n, 1), "misfit": 0.8}, T0 + 30 * n, T0 + 30 * n + 8,
                              62000.0)
    assert log.write_pass({**p(3, 1, valid=False), "misfit": 99.0}, T0 + 90, T0 + 98,
                          62000.0)
    log.close()
    r = PassLog(path, "s1").restore("calib-a")
    assert r.recent_misfits == [0.8, 0.8] and r.next_pass == 4


def test_a_meta_record_that_is_not_the_daemons_is_not_trusted(tmp_path: Path) -> None:
    """A pass log whose record of the params' first pass was edited into something else:
    a note then says nothing of any pass (the report keeps what was said before), and the
    restore starts those params afresh and writes the record again."""
    from shoveld.daemon.persist import read_calibrations

    path = db_path(tmp_path)
    log = PassLog(path, "s1")
    log.restore("calib-a")
    log.note_calibration("the model lacks something")
    assert read_calibrations(path) == [("the model lacks something", 1, None)]
    log.con.execute("UPDATE meta SET value = 'x' WHERE key = 'params_from_pass'")
    log.note_calibration("something else")
    assert read_calibrations(path) == [("the model lacks something", 1, None)]
    r = log.restore("calib-a")
    assert (r.recent_misfits, r.empty_checks) == ([], [])
    log.note_calibration("the model lacks something")
    assert read_calibrations(path) == [("the model lacks something", 1, None)]
    log.close()


def test_each_params_note_is_kept_from_its_first_pass(tmp_path: Path) -> None:
    """Params that said the model lacks something, then others that said nothing, then
    the first again: each note with the passes weighed with its params, the earlier ones
    kept when other params come (until the thirty-third session only the last params'
    note was kept); a log from before the table has none, and no traceback."""
    from shoveld.daemon.persist import read_calibrations

    path = db_path(tmp_path)
    log = PassLog(path, "s1")

    def passes(first: int, n: int) -> None:
        for k in range(first, first + n):
            log.write_pass({"pass": k, "truck": 1, "payload_kg": 30000.0, "std_kg": 300.0,
                            "start_s": 60.0 * k, "end_s": 60.0 * k + 20, "samples": 500,
                            "valid": True, "reason": ""}, 1e9 + 60 * k, 1e9 + 60 * k + 20,
                           136000.0)

    for params, note, n in (("calib-a", "lacks a swing", 3), ("calib-b", "", 2),
                            ("calib-a", "lacks a swing", 1)):
        log.restore(params)
        log.note_calibration(note)
        passes(log.restore(params).next_pass, n)
    log.restore("calib-a")  # a restart with the same params: the same record
    log.note_calibration("lacks a swing")
    assert read_calibrations(path) == [("lacks a swing", 1, 3), ("lacks a swing", 6, None)]
    log.con.execute("DROP TABLE calibrations")
    assert read_calibrations(path) == []
    log.close()
