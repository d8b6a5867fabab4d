"""``shoveld report``: a shift's pass log, written through the daemon's own pass-log API,
turned into the supervisor's page and tables; the figures against sums made here."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from shoveld.cli import main
from shoveld.daemon.persist import PassLog, db_path

T0 = 1_790_000_000.0
TARGET = 136000.0


def shift(tmp_path: Path) -> tuple[Path, list[dict[str, Any]]]:
    """Six trucks over about three hours: one over 110 %, passes not weighed, one truck
    left open."""
    rng = np.random.default_rng(4)
    log = PassLog(db_path(tmp_path), "s1")
    made: list[dict[str, Any]] = []
    t, n = T0, 0
    for truck in range(1, 7):
        loads = [float(x) for x in rng.uniform(28000, 36000, 4)]
        if truck == 3:
            loads = [33000.0] * 4 + [20000.0]  # 111.8 %: over 110 %, not 120 %
        for k, kg in enumerate(loads):
            n += 1
            valid = not (truck == 2 and k == 1)
            p = {"pass": n, "truck": truck, "payload_kg": kg if valid else None,
                 "std_kg": 300.0 if valid else None, "start_s": t - T0, "end_s": t - T0 + 20,
                 "samples": 500, "valid": valid, "reason": "" if valid else "laser silent"}
            log.write_pass(p, t, t + 20.0, TARGET)
            made.append({**p, "end": t + 20.0})
            t += 45.0 + float(rng.uniform(0, 10))
        if truck < 6:
            log.close_truck(truck, TARGET, t)
            t += 600.0
    log.close()
    return db_path(tmp_path), made


def test_report_tables_and_page(tmp_path: Path) -> None:
    db, made = shift(tmp_path)
    out = tmp_path / "report"
    assert main(["report", "--db", str(db), "--out", str(out)]) == 0
    trucks = {int(r["truck"]): r for r in csv.DictReader(open(out / "trucks.csv"))}
    assert sorted(trucks) == [1, 2, 3, 4, 5, 6]
    for k, r in trucks.items():
        want = sum(p["payload_kg"] for p in made if p["truck"] == k and p["valid"])
        assert float(r["total_kg"]) == pytest.approx(want, abs=0.05)
        assert r["closed"] == ("1" if k < 6 else "0")
    assert trucks[3]["status"] == "over_110" and trucks[2]["invalid_passes"] == "1"
    # truck 2's pass not weighed: its total is a lower bound, neither under nor ok
    assert trucks[2]["status"] == "incomplete"
    assert {trucks[k]["status"] for k in (1, 4, 5)} <= {"under", "ok"}
    hours = list(csv.DictReader(open(out / "hours.csv")))
    assert sum(float(h["tonnes"]) for h in hours) == pytest.approx(
        sum(p["payload_kg"] for p in made if p["valid"]) / 1000, abs=0.05)
    assert sum(int(h["passes"]) for h in hours) == len(made)
    page = (out / "index.html").read_text()
    # the 10/10/20 line over the closed trucks whose passes were all weighed: one of four
    # over 110 % is 25 %; truck 2, with a pass not weighed, is said not to be judged
    assert "4 trucks" in page and "25.0 % over 110 %" in page and "OUTSIDE the rule" in page
    assert "1 truck with a pass not weighed was not judged" in page
    row2 = page[page.index("<td>2</td>", page.index("id='trucks'")):]
    assert row2.startswith("<td>2</td><td>4 (1 not weighed)</td><td>&ge; ")
    assert "laser silent" in page
    assert page.count("data:image/png;base64,") == 4  # every plot inside the one file
    for name in ("tonnes_per_hour", "pass_payloads", "truck_fill", "cycle_times"):
        assert (out / f"{name}.png").stat().st_size > 5000


def test_passes_not_weighed_are_counted_by_the_kind_of_reason(tmp_path: Path) -> None:
    """Reasons that differ only in their numbers are one kind; the table keeps each."""
    log = PassLog(db_path(tmp_path), "s1")
    reasons = ["the crowd laser changed target 12.3 s into the pass",
               "only 12 valid samples in lift and swing (1,030 invalid)",
               "the crowd laser changed target 4.0 s into the pass"]
    for n, why in enumerate(reasons, 1):
        t = T0 + 50.0 * n
        log.write_pass({"pass": n, "truck": 1, "payload_kg": None, "std_kg": None,
                        "start_s": t - T0, "end_s": t - T0 + 20, "samples": 12,
                        "valid": False, "reason": why}, t, t + 20.0, TARGET)
    log.close()
    out = tmp_path / "r"
    assert main(["report", "--db", str(db_path(tmp_path)), "--out", str(out)]) == 0
    page = (out / "index.html").read_text()
    assert all(why in page for why in reasons)
    assert ("By reason: the crowd laser changed target N s into the pass: 2; "
            "only N valid samples in lift and swing (N invalid): 1</p>") in page


def test_report_of_a_period_and_of_an_empty_log(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    db, made = shift(tmp_path)
    out = tmp_path / "r2"
    since = str(made[10]["end"] - 1)
    assert main(["report", "--db", str(db), "--out", str(out), "--since", since]) == 0
    rows = list(csv.DictReader(open(out / "passes.csv")))
    assert len(rows) == len(made) - 10
    assert main(["report", "--db", str(db), "--out", str(tmp_path / "r3"), "--since",
                 str(T0 + 10 * 86400)]) == 0
    assert "No truck was closed" in (tmp_path / "r3" / "index.html").read_text()
    assert main(["report", "--db", str(tmp_path / "none.sqlite"), "--out",
                 str(tmp_path / "r4")]) == 2
    assert "none.sqlite" in capsys.readouterr().err


def test_one_truck_and_one_pass_are_said_in_the_singular(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The first truck of a shift (two passes, one dump-to-dump cycle), then a period
    holding only its last pass: "1 truck", "1 cycle", "1 pass", never "1 trucks"."""
    log = PassLog(db_path(tmp_path), "s1")
    for n, t in ((1, T0), (2, T0 + 50.0)):
        p = {"pass": n, "truck": 1, "payload_kg": 68000.0, "std_kg": 300.0,
             "start_s": t - T0, "end_s": t - T0 + 20, "samples": 500, "valid": True,
             "reason": ""}
        log.write_pass(p, t, t + 20.0, TARGET)
    log.close_truck(1, TARGET, T0 + 100.0)
    log.close()
    db = db_path(tmp_path)
    assert main(["report", "--db", str(db), "--out", str(tmp_path / "a")]) == 0
    assert "(2 passes, 1 truck, 136.0 t)" in capsys.readouterr().out
    page = (tmp_path / "a" / "index.html").read_text()
    assert "2 passes (0 not weighed) &middot; 1 truck &middot;" in page
    assert "<p id='rule'>1 truck, mean 136.0 t" in page
    assert "over 1 cycle.</p>" in page
    assert main(["report", "--db", str(db), "--out", str(tmp_path / "b"), "--since",
                 str(T0 + 60.0)]) == 0
    assert "(1 pass, 1 truck, 68.0 t)" in capsys.readouterr().out
    page = (tmp_path / "b" / "index.html").read_text()
    assert "1 pass (0 not weighed) &middot; 1 truck &middot;" in page


def test_the_passes_the_model_did_not_fit_are_named(tmp_path: Path) -> None:
    """A pass's misfit above the warning level is named with the pass; a log written
    before misfits were recorded says so rather than "none"."""
    log = PassLog(db_path(tmp_path), "s1")
    fits = [0.8, 0.7, 24.6, 0.9, 3.4]
    for n, m in enumerate(fits, 1):
        t = T0 + 50.0 * n
        valid = n != 5
        log.write_pass({"pass": n, "truck": 1, "payload_kg": 30000.0 + n if valid else None,
                        "std_kg": 300.0 if valid else None, "start_s": t - T0,
                        "end_s": t - T0 + 20, "samples": 500, "valid": valid,
                        "reason": "" if valid else "the crowd laser changed target 3.0 s "
                        "into the pass", "misfit": m}, t, t + 20.0, TARGET)
    log.close()
    out = tmp_path / "r"
    assert main(["report", "--db", str(db_path(tmp_path)), "--out", str(out)]) == 0
    page = (out / "index.html").read_text()
    assert "Median 0.90 over 5 passes" in page and "2 passes above 3" in page
    table = page.split("<table id='misfits'>")[1].split("</table>")[0]
    assert table.count("<tr>") == 3  # the header and passes 3 and 5, not the others
    assert "<td>3</td><td>1</td>" in table and "<td>30.0</td><td>24.6</td>" in table
    assert "not weighed</td><td>3.4</td>" in table
    rows = list(csv.DictReader(open(out / "passes.csv")))
    assert [r["misfit"] for r in rows] == ["0.80", "0.70", "24.60", "0.90", "3.40"]

    db, _ = shift(tmp_path / "old")  # passes written without a misfit
    assert main(["report", "--db", str(db), "--out", str(tmp_path / "r2")]) == 0
    page = (tmp_path / "r2" / "index.html").read_text()
    assert "records no misfit" in page and "id='misfits'" not in page


def test_the_empty_dipper_on_the_returns_is_reported_with_the_daemons_verdict(
        tmp_path: Path) -> None:
    """The returns' checks as the daemon kept them: their spread, the moment the median
    went beyond the daemon's level (named with the causes), the plot and the table; a
    log that records none says so."""
    db, made = shift(tmp_path)
    log = PassLog(db, "s1")
    kgs = [40.0, -85.0, 1610.0, 1720.0, 1655.0, 1590.0, 1700.0, 1688.0]
    for k, (p, kg) in enumerate(zip(made, kgs, strict=False)):
        med = float(np.median(kgs[max(0, k - 4):k + 1]))
        log.write_empty({"after_pass": p["pass"], "end_s": 0.0, "payload_kg": kg,
                         "std_kg": 90.0, "samples": 100, "median_kg": med},
                        p["end"] + 6.0, 500.0, k >= 4 and abs(med) > 500.0)
    log.close()
    out = tmp_path / "r"
    assert main(["report", "--db", str(db), "--out", str(out)]) == 0
    page = (out / "index.html").read_text()
    section = page.split("<h2>The empty dipper on the returns</h2>")[1]
    assert "8 returns: median +1655 kg, from -85 to +1720 kg" in section
    assert "at the end +1688 kg, against the daemon's level of ±500 kg" in section
    # the fifth check was the first with five returns, median 1610 kg: beyond
    assert ("<p id='empty' class='bad'>The median of the last returns was beyond the level "
            "at 4 returns, the first ending") in section
    assert "(median +1610 kg)" in section and "calibrate again" in section
    assert "alt='the empty dipper on the returns'" in section
    assert (out / "empty_dipper.png").stat().st_size > 5000
    rows = list(csv.DictReader(open(out / "empties.csv")))
    assert [float(r["empty_kg"]) for r in rows] == kgs
    assert [r["beyond"] for r in rows] == ["0"] * 4 + ["1"] * 4
    assert "empties.csv" in page

    # a log of schema 2, which the daemon has not opened since: said, not "none"
    import sqlite3

    con = sqlite3.connect(db)
    con.execute("DROP TABLE empties")
    con.commit()
    con.close()
    assert main(["report", "--db", str(db), "--out", str(tmp_path / "r2")]) == 0
    page = (tmp_path / "r2" / "index.html").read_text()
    assert "records no empty-dipper checks" in page and "empties.csv" not in page
    assert not (tmp_path / "r2" / "empties.csv").exists()


def test_the_calibration_is_said_of_the_passes_weighed_with_it(tmp_path: Path) -> None:
    """The daemon keeps what its params say of their calibration, and from which pass it
    ran with them: the report says it of this period's passes from that one on, and not
    of a period before it."""
    db, made = shift(tmp_path)
    log = PassLog(db, "s1")
    log.restore("calib-a")  # these params from pass 26 on (the log holds 25)
    log.note_calibration("the calibration's passes fit worse than its trials (hoist 2.6 "
                         "times): above 1.5, the model lacks something")
    t = made[-1]["end"] + 60.0
    for n in (26, 27):
        log.write_pass({"pass": n, "truck": 6, "payload_kg": 30000.0, "std_kg": 300.0,
                        "start_s": t - T0, "end_s": t - T0 + 20, "samples": 500,
                        "valid": True, "reason": ""}, t, t + 20.0, TARGET)
        t += 60.0
    log.close()

    def page(*window: str) -> str:
        out = tmp_path / f"r{len(window)}"
        assert main(["report", "--db", str(db), "--out", str(out), *window]) == 0
        return (out / "index.html").read_text()

    assert len(made) == 25
    said = ("<p class='calibration bad'>2 passes of this period (pass 26 on) were weighed "
            "with params whose calibration said: the calibration&#x27;s passes fit worse "
            "than its trials (hoist 2.6 times): above 1.5, the model lacks something.</p>")
    assert said in page()
    before = page("--until", str(made[-1]["end"] + 1.0))
    assert "id='calibration'" not in before and "25 passes" in before
    # new params that say nothing, and a pass weighed with them: the earlier params' note
    # stays with the passes weighed with them, and says where they ended
    log = PassLog(db, "s1")
    log.restore("calib-b")
    log.note_calibration("")
    log.write_pass({"pass": 28, "truck": 6, "payload_kg": 30000.0, "std_kg": 300.0,
                    "start_s": t - T0, "end_s": t - T0 + 20, "samples": 500,
                    "valid": True, "reason": ""}, t, t + 20.0, TARGET)
    log.close()
    text = page()
    assert said.replace("(pass 26 on)", "(pass 26 to 27)") in text
    assert text.count("class='calibration bad'") == 1
    # nothing to say of any params: no section
    log = PassLog(db, "s1")
    log.restore("calib-a")
    log.note_calibration("")
    log.con.execute("UPDATE calibrations SET note = ''")
    log.close()
    assert "id='calibration'" not in page()
