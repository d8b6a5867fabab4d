"""The signals-table reader: round trip, and an error naming file, line and column."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from shoveld.signals import COLUMN_NAMES, SignalsFormatError, SignalsTable, read_table, write_table

HEADER = ",".join(COLUMN_NAMES)
ROW = "{t},10.5,8.2,30,45,400,390,70,50,29,0,30,0.1,-0.2,"


def _write(tmp_path: Path, body: str, name: str = "t.csv") -> Path:
    p = tmp_path / name
    p.write_text(body, encoding="utf-8")
    return p


def test_round_trip(tmp_path: Path) -> None:
    t = np.arange(5) * 0.02
    table = SignalsTable.from_arrays(meta={"known_payload_kg": "8420"}, time_s=t,
                                     handle_deg=np.linspace(-40, 20, 5), crowd_m=np.full(5, 8.0),
                                     hoist1_a=np.array([1.5, np.nan, 3, 4, 5]))
    p = tmp_path / "x.csv"
    write_table(p, table)
    back = read_table(p)
    assert back.meta["format"] == "shovel-signals/1"
    assert back.known_payload_kg == 8420.0
    np.testing.assert_allclose(back.time, t)
    np.testing.assert_allclose(back["handle_deg"], table["handle_deg"])
    assert np.isnan(back["hoist1_a"][1]) and np.isnan(back["boom_deg"]).all()
    assert np.all(back.payload_truth() == 8420.0)


def test_valid_minimal(tmp_path: Path) -> None:
    body = "# format: shovel-signals/1\n# sample_rate_hz: 50\n" + HEADER + "\n" + "\n".join(
        ROW.format(t=k * 0.02) for k in range(3)) + "\n"
    table = read_table(_write(tmp_path, body))
    assert len(table) == 3 and table.sample_rate_hz == 50.0


@pytest.mark.parametrize(("body", "line", "column", "words"), [
    (HEADER + "\n" + ROW.format(t=0) + "\n" + ROW.format(t=0.02).replace(",8.2,", ",400,") + "\n",
     3, "crowd_m", "outside the plausible range"),
    (HEADER + "\n" + ROW.format(t=0.04) + "\n" + ROW.format(t=0.02) + "\n",
     3, "time_s", "strictly increasing"),
    (HEADER + "\n" + ROW.format(t=0) + "\n" + ROW.format(t=0.02).replace(",400,", ",nan,") + "\n",
     3, "hoist1_a", "not a finite number"),
    (HEADER + "\n" + ROW.format(t=0).replace(",45,", ",abc,") + "\n", 2, "boom_deg",
     "expected a number"),
    (HEADER.replace(",swing_a", "") + "\n", 1, "swing_a", "missing column"),
    (HEADER + "\n" + ROW.format(t=0) + ",7\n", 2, None, "expected 15 values"),
    ("# format: shovel-signals/9\n" + HEADER + "\n", 1, None, "understands"),
    ("# known_payload_kg: heavy\n" + HEADER + "\n", 1, None, "must be a number"),
    (HEADER + "\n", 2, None, "no data rows"),
    (HEADER + "\n" + ",10,8,0,45,1,1,70,1,29,1,30,0,0,\n", 2, "time_s", "blank"),
])
def test_errors_name_line_and_column(tmp_path: Path, body: str, line: int, column: str | None,
                                     words: str) -> None:
    p = _write(tmp_path, body)
    with pytest.raises(SignalsFormatError) as ei:
        read_table(p)
    e = ei.value
    assert e.path == str(p)
    assert e.line == line
    assert e.column == column
    assert words in str(e)
    assert str(p) in str(e)


def test_columns_out_of_order(tmp_path: Path) -> None:
    cols = list(COLUMN_NAMES)
    cols[1], cols[2] = cols[2], cols[1]
    with pytest.raises(SignalsFormatError, match="out of order"):
        read_table(_write(tmp_path, ",".join(cols) + "\n"))


def test_not_utf8(tmp_path: Path) -> None:
    p = tmp_path / "bin.csv"
    p.write_bytes(b"\xff\xfe" + HEADER.encode())
    with pytest.raises(SignalsFormatError, match="not UTF-8"):
        read_table(p)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SignalsFormatError, match="cannot read"):
        read_table(tmp_path / "nope.csv")


def test_a_cell_too_long_for_csv_is_a_format_error_with_its_line() -> None:
    from shoveld.signals.columns import COLUMN_NAMES
    from shoveld.signals.table import SignalsFormatError, read_table

    text = "# format: shovel-signals/1\n" + ",".join(COLUMN_NAMES) + "\n" + "9" * 200_000 + "\n"
    with pytest.raises(SignalsFormatError, match=r"t\.csv:3: not a CSV row"):
        read_table("t.csv", text)


def test_the_fast_path_and_the_cell_by_cell_path_read_the_same_table(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import shoveld.signals.table as T
    from shoveld.sim.scenario import simulate_cycles

    tab = simulate_cycles(2, seed=3, verified_fraction=1.0).table
    tab.columns["boom_deg"][5:9] = np.nan  # blanks, at the start and inside rows
    tab.columns["time_s"][:] = tab.columns["time_s"] + 0.0
    path = tmp_path / "t.csv"
    T.write_table(path, tab)
    monkeypatch.setattr(T, "CHUNK_ROWS", 1000)  # several chunks, both sides of a join
    monkeypatch.setattr(T, "ARROW_BLOCK_BYTES", 50_000)  # and several blocks
    fast = T.read_table(path)
    monkeypatch.setattr(T, "_read_fast", lambda data, offset: None)
    slow = T.read_table(path)
    for name in fast.columns:
        assert np.array_equal(fast.columns[name], slow.columns[name], equal_nan=True), name
    assert np.isnan(fast.columns["boom_deg"][5:9]).all()


@pytest.mark.parametrize("bad,what", [("nan", "not a finite number"),
                                      ("NaN", "not a finite number"),
                                      ("1#2", "expected a number"),
                                      ("inf", "not a finite number"),
                                      ("-inf", "not a finite number"),
                                      ("1e999", "not a finite number")])
def test_what_the_fast_parser_would_take_is_still_refused(tmp_path: Path, bad: str,
                                                          what: str) -> None:
    from shoveld.signals.columns import COLUMN_NAMES
    from shoveld.signals.table import SignalsFormatError, read_table, write_table
    from shoveld.sim.scenario import simulate_cycles

    tab = simulate_cycles(1, seed=3).table
    path = tmp_path / "t.csv"
    write_table(path, tab.slice(tab.time < 1.0))
    lines = path.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("time_s")) + 3
    cells = lines[k].split(",")
    cells[COLUMN_NAMES.index("hoist1_a")] = bad
    lines[k] = ",".join(cells)
    with pytest.raises(SignalsFormatError, match=rf"t\.csv:{k + 1} column 'hoist1_a'.*{what}"):
        read_table("t.csv", "\n".join(lines) + "\n")


def test_every_columns_range_is_finite() -> None:
    """The fast path refuses infinities by the columns' ranges alone."""
    from shoveld.signals.columns import COLUMNS

    assert all(np.isfinite([c.lo, c.hi]).all() for c in COLUMNS)


def test_samples_come_out_row_by_row_across_chunks() -> None:
    """The rows become Python floats a chunk at a time (memory); every row comes out once,
    in order, across the chunk edges, NaN (an unknown cell) included."""
    from shoveld.sample import SAMPLE_CHUNK, samples_from_table

    n = 2 * SAMPLE_CHUNK + 7
    rng = np.random.default_rng(0)
    cols: dict[str, np.ndarray] = {c: rng.normal(size=n) for c in COLUMN_NAMES}
    cols["time_s"] = np.arange(n) * 0.02
    cols["crowd_a"][SAMPLE_CHUNK] = np.nan
    table = SignalsTable.from_arrays(meta={"sample_rate_hz": "50"}, **cols)
    got = list(samples_from_table(table))
    assert len(got) == n
    for i in (0, SAMPLE_CHUNK - 1, SAMPLE_CHUNK, SAMPLE_CHUNK + 1, n - 1):
        for c in COLUMN_NAMES:
            want = float(table.columns[c][i])
            have = getattr(got[i], c)
            assert have == want or (np.isnan(want) and np.isnan(have)), (i, c)


_ODD_CELLS = ("", " ", "nan", "NaN", "inf", "-inf", "1e3", "1E-2", "+1", "-0", ".5", "5.",
              "1_0", "0x1f", "abc", '"1"', "1#2", " 2 ", "--1", "1e999", "7,", "\t3", "1 2",
              "Infinity", "+.5", "1e+3", "1e", "e3", ".", "-", "+", "0x1p3", "\u0661", "1'2")


Read = SignalsTable | tuple[str, int | None, str | None]
"""A table read, or the error's text, line and column."""


def _read_both(text: str, chunk_rows: int) -> tuple[Read, Read]:
    """The table (or the error's text, line and column) by the default reader and by the
    cell-by-cell path alone; ``chunk_rows`` sets the size of both paths' pieces: rows for
    the cell-by-cell reader, 100 bytes each for Arrow's blocks (a row or a few)."""
    import shoveld.signals.table as T

    def read() -> Read:
        try:
            tab = T.read_table("t.csv", text)
        except SignalsFormatError as e:
            return (str(e), e.line, e.column)
        return tab

    saved = T.CHUNK_ROWS, T.ARROW_BLOCK_BYTES, T._read_fast
    try:
        T.CHUNK_ROWS, T.ARROW_BLOCK_BYTES = chunk_rows, 100 * chunk_rows
        fast = read()
        T._read_fast = lambda data, offset: None
        slow = read()
    finally:
        T.CHUNK_ROWS, T.ARROW_BLOCK_BYTES, T._read_fast = saved
    return fast, slow


@settings(max_examples=400, deadline=None)
@given(st.data())
def test_the_fast_path_and_the_cell_by_cell_path_agree_on_any_rows(data: st.DataObject) -> None:
    """Rows of numbers in the writer's and other spellings, blanks anywhere, and now and
    then a cell or a row that must be refused: the same table or the same error, whatever
    the size of the pieces (several grow the columns)."""
    from shoveld.signals.columns import COLUMNS
    from shoveld.signals.table import _fmt

    n = data.draw(st.integers(1, 9), label="rows")
    blank_pct = data.draw(st.sampled_from([0, 3, 30]), label="% blank")
    odd_pct = data.draw(st.sampled_from([0, 0, 1, 10]), label="% odd")
    payload_blank = data.draw(st.booleans(), label="payload blank")
    rows = []
    for k in range(n):
        cells = []
        for col in COLUMNS:
            kind = data.draw(st.integers(0, 99))
            if kind < odd_pct:
                cells.append(data.draw(st.sampled_from(_ODD_CELLS)) if kind % 2 else
                             _fmt(col.hi * 2 + 1))  # out of range
            elif col.name == "time_s":  # now and then the previous row's time
                cells.append(_fmt((k - (kind >= 97 and k > 0)) * 0.02))
            elif kind < odd_pct + blank_pct or (payload_blank and col.name == "payload_kg"):
                cells.append("")
            else:
                v = data.draw(st.floats(col.lo, col.hi))
                cells.append(_fmt(v) if kind < 60 else repr(v) if kind < 80 else f"{v:.3f}")
        rows.append(",".join(cells))
    if data.draw(st.integers(0, 5)) == 0:
        rows.insert(data.draw(st.integers(0, n)), "")
    end = data.draw(st.sampled_from(["\n", "\r\n"]))
    text = "# format: shovel-signals/1\n" + HEADER + end + end.join(rows) + end
    fast, slow = _read_both(text, data.draw(st.integers(1, 4)))
    if isinstance(slow, tuple):
        assert fast == slow
    else:
        assert isinstance(fast, SignalsTable)
        for name in COLUMN_NAMES:
            a, b = fast.columns[name], slow.columns[name]
            assert a.shape == b.shape and a.flags.c_contiguous, name
            assert np.array_equal(a, b, equal_nan=True), name
            assert np.array_equal(np.signbit(a), np.signbit(b)), name  # -0 stays -0


def test_blanks_at_row_ends_and_inside_rows_are_read_by_the_fast_path_itself(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Blanks are null to Arrow and NaN in the table, with no second read: the fast path
    returns the rows itself (a fast path that always gave way would pass the comparisons
    above and be slow), the same table as cell by cell."""
    import shoveld.signals.table as T

    body = [ROW.format(t=k * 0.02) for k in range(6)]
    body[4] = body[4].replace(",30,45,", ",,45,")
    text = HEADER + "\n" + "\n".join(body) + "\n"
    taken: list[T._Columns | None] = []
    fast_read = T._read_fast

    def read_fast(data: Callable[[], BinaryIO], offset: int) -> T._Columns | None:
        taken.append(fast_read(data, offset))
        return taken[-1]
    monkeypatch.setattr(T, "_read_fast", read_fast)
    fast, slow = _read_both(text, 20_000)
    assert isinstance(taken[0], T._Columns) and taken[0].rows == 6
    assert isinstance(fast, SignalsTable) and isinstance(slow, SignalsTable)
    for name in COLUMN_NAMES:
        assert np.array_equal(fast.columns[name], slow.columns[name], equal_nan=True), name
    assert np.isnan(fast["swing_deg"][4]) and np.isnan(fast["payload_kg"]).all()
    # and what it gives way on: a quoted number (read cell by cell into the same table)
    taken.clear()
    quoted = read_table("t.csv", text.replace(",10.5,", ',"10.5",', 1))
    assert taken == [None]
    for name in COLUMN_NAMES:
        assert np.array_equal(quoted.columns[name], fast.columns[name], equal_nan=True), name
