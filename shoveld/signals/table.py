"""Reader and writer of signals tables (UTF-8 CSV, ``shovel-signals/1``).

The reader refuses rather than guesses: every error names the file, the line and
the column, and what was expected. Blank cells are allowed (unknown value) and
become NaN in memory; a literal ``nan`` in the file is rejected because it hides
whether the value was unknown or broken.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, TextIO

import numpy as np

from shoveld.signals.columns import BY_NAME, COLUMN_NAMES, FORMAT_NAME
from shoveld.words import n_of


class SignalsFormatError(ValueError):
    """A signals table that does not follow ``shovel-signals/1``."""

    def __init__(self, path: str, line: int | None, column: str | None, message: str) -> None:
        where = path
        if line is not None:
            where += f":{line}"
        if column is not None:
            where += f" column '{column}'"
        super().__init__(f"{where}: {message}")
        self.path = path
        self.line = line
        self.column = column


@dataclass
class SignalsTable:
    """A whole table in memory: one float64 array per column (NaN where blank)."""

    columns: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    source: str = "<memory>"

    def __len__(self) -> int:
        return int(self.columns["time_s"].shape[0])

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    @property
    def time(self) -> np.ndarray:
        return self.columns["time_s"]

    @property
    def sample_rate_hz(self) -> float:
        """Declared rate, or the median rate of the time axis."""
        if "sample_rate_hz" in self.meta:
            return float(self.meta["sample_rate_hz"])
        t = self.time
        if len(t) < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(t)))

    @property
    def known_payload_kg(self) -> float | None:
        v = self.meta.get("known_payload_kg")
        return float(v) if v not in (None, "") else None

    def payload_truth(self) -> np.ndarray:
        """Per-sample known payload: the column where filled, else ``known_payload_kg``."""
        p = self.columns["payload_kg"].copy()
        k = self.known_payload_kg
        if k is not None:
            p[np.isnan(p)] = k
        return p

    def slice(self, mask: np.ndarray) -> SignalsTable:
        return SignalsTable({k: v[mask] for k, v in self.columns.items()}, dict(self.meta),
                            self.source)

    @classmethod
    def from_arrays(cls, meta: dict[str, str] | None = None, **cols: Iterable[float]
                    ) -> SignalsTable:
        """Build a table; missing columns are filled with NaN (unknown)."""
        n = len(np.asarray(cols["time_s"]))
        out = {}
        for name in COLUMN_NAMES:
            if name in cols:
                a = np.asarray(cols[name], dtype=float)
                if a.shape != (n,):
                    raise ValueError(f"column {name}: expected {n_of(n, 'value', 'values')}, "
                                     f"got {a.shape}")
                out[name] = a
            else:
                out[name] = np.full(n, np.nan)
        unknown = set(cols) - set(COLUMN_NAMES)
        if unknown:
            raise ValueError(f"unknown columns {sorted(unknown)}; expected {COLUMN_NAMES}")
        m = {"format": FORMAT_NAME}
        m.update(meta or {})
        return cls(out, m)


def _parse_meta(path: str, lineno: int, text: str, meta: dict[str, str]) -> None:
    body = text[1:].strip()
    if not body:
        return
    if ":" not in body:
        raise SignalsFormatError(path, lineno, None,
                                 f"metadata line must be '# key: value', got {text!r}")
    key, value = (s.strip() for s in body.split(":", 1))
    if key == "format" and value != FORMAT_NAME:
        raise SignalsFormatError(path, lineno, None,
                                 f"format is {value!r}; this reader understands {FORMAT_NAME!r}")
    if key in ("sample_rate_hz", "known_payload_kg"):
        try:
            v = float(value)
        except ValueError:
            raise SignalsFormatError(path, lineno, None,
                                     f"'{key}' must be a number, got {value!r}") from None
        if not math.isfinite(v) or (key == "sample_rate_hz" and v <= 0) or (
                key == "known_payload_kg" and not 0 <= v <= 150000):
            raise SignalsFormatError(path, lineno, None, f"'{key}' out of range: {value!r}")
    meta[key] = value


CHUNK_ROWS = 20_000
"""Rows parsed at a time by the cell-by-cell reader: the file is streamed, so memory is the
table's arrays plus one chunk, whatever the length of the recording."""

ARROW_BLOCK_BYTES = 1 << 18
"""Bytes Arrow's CSV reader parses at a time (a batch of about 2,000 rows): the fast path
streams too. Arrow's buffers grow with the block: 1 MiB blocks read an hour 7 % faster
(0.113 against 0.121 s) and held 31 MiB more at the peak of a 3-hour table."""


def read_table(path: str | Path, text: str | None = None) -> SignalsTable:
    """Read and validate a signals table; raise :class:`SignalsFormatError` on any fault.

    The rows are read twice at most: Arrow's CSV reader parses them in blocks and the
    checks (blank times, ranges, increasing time) run on whole columns; if it refuses
    anything (a word, a quote, a short row, a value out of range) the rows are read again
    cell by cell, which names the line and the column of the first fault, or reads what
    Arrow would not (a quoted number) into the same table.
    """
    spath = str(path)
    if text is None:
        try:
            f: Any = open(path, encoding="utf-8", newline="")
        except OSError as e:
            raise SignalsFormatError(spath, None, None, f"cannot read: {e.strerror}") from None

        def data() -> BinaryIO:
            return open(path, "rb")
    else:
        f = io.StringIO(text, newline="")

        def data() -> BinaryIO:
            return io.BytesIO(text.encode("utf-8"))  # a lone surrogate raises: cell by cell
    with f:
        try:
            return _read(spath, f, data)
        except UnicodeDecodeError as e:
            raise SignalsFormatError(spath, None, None,
                                     f"not UTF-8 (byte offset {e.start})") from None


def _read(spath: str, f: Any, data: Callable[[], BinaryIO]) -> SignalsTable:
    meta: dict[str, str] = {}
    lineno = 0
    offset = 0  # bytes before the first row: where the fast path starts
    header_text = None
    for raw in f:
        lineno += 1
        offset += len(raw.encode("utf-8", "surrogatepass"))  # newline="": as in the file
        line = raw.rstrip("\r\n")
        if line.startswith("#"):
            _parse_meta(spath, lineno, line, meta)
        elif line.strip():
            header_text = line
            break
    if header_text is None:
        raise SignalsFormatError(spath, None, None, "no header line (expected the column names)")
    header_line = lineno
    try:
        header = [h.strip() for h in next(csv.reader([header_text.lstrip("\ufeff")]))]
    except csv.Error as e:
        raise SignalsFormatError(spath, header_line, None,
                                 f"not a CSV header line ({e})") from None
    missing = [c for c in COLUMN_NAMES if c not in header]
    if missing:
        raise SignalsFormatError(spath, header_line, missing[0],
                                 f"missing column(s) {missing}; expected {list(COLUMN_NAMES)}")
    if tuple(header) != COLUMN_NAMES:
        extra = [h for h in header if h not in COLUMN_NAMES]
        what = f"unknown column(s) {extra}" if extra else "columns out of order"
        raise SignalsFormatError(spath, header_line, extra[0] if extra else None,
                                 f"{what}; expected exactly {list(COLUMN_NAMES)}")
    columns = _read_fast(data, offset)
    if columns is None:
        columns = _Columns()
        prev: tuple[float, int] | None = None  # the last row's time and line
        first = header_line + 1
        while True:
            chunk = [ln.rstrip("\r\n") for ln in itertools.islice(f, CHUNK_ROWS)]
            if not chunk:
                break
            arr, prev = _slow_chunk(spath, chunk, first, prev)
            columns.append(list(arr.T))
            first += len(chunk)
    if not columns.rows:
        raise SignalsFormatError(spath, header_line + 1, None, "no data rows")
    return SignalsTable(columns.finish(), meta, spath)


class _Columns:
    """The table's columns, filled a block at a time.

    Each column is one array, doubled when full (a tail never written costs no memory)
    and trimmed at the end: memory is one table, where joining the blocks' rows and then
    taking the columns out of them held two.
    """

    def __init__(self) -> None:
        self.rows = 0
        self.cols = [np.empty(CHUNK_ROWS) for _ in COLUMN_NAMES]

    def append(self, block: Sequence[np.ndarray]) -> None:
        """One array per column, all of one length."""
        end = self.rows + len(block[0])
        for j, col in enumerate(self.cols):
            if end > len(col):
                grown = np.empty(max(2 * len(col), end))
                grown[:self.rows] = col[:self.rows]
                self.cols[j] = col = grown
            col[self.rows:end] = block[j]
        self.rows = end

    def finish(self) -> dict[str, np.ndarray]:
        for col in self.cols:
            col.resize(self.rows, refcheck=False)  # in place: no copy of the column
        return dict(zip(COLUMN_NAMES, self.cols, strict=True))


def _read_fast(data: Callable[[], BinaryIO], offset: int) -> _Columns | None:
    """The rows from ``offset`` on, parsed by Arrow's CSV reader a block at a time and
    checked column-wise; None if Arrow refuses them or a check fails: then the cell-by-cell
    reader reads them again, and names the fault if there is one.

    Arrow, not numpy's loadtxt: 0.12 against 0.52 s for an hour of 50 Hz rows, the same
    floats to the bit (both round correctly). Quotes are not special here (a quoted cell is
    not a number, so the cell-by-cell reader takes it), a blank cell is null (unknown:
    NaN), and Arrow's own spellings of NaN and infinity, which the format refuses, fail the
    checks below.
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv

    columns = _Columns()
    last = -math.inf  # the time of the last row read
    try:
        with data() as src:
            src.seek(offset)
            reader = pacsv.open_csv(
                src,
                read_options=pacsv.ReadOptions(column_names=list(COLUMN_NAMES),
                                               use_threads=False,
                                               block_size=ARROW_BLOCK_BYTES),
                parse_options=pacsv.ParseOptions(quote_char=False),
                convert_options=pacsv.ConvertOptions(
                    column_types={name: pa.float64() for name in COLUMN_NAMES},
                    null_values=[""]),
                memory_pool=pa.system_memory_pool())
            for batch in reader:
                if not batch.num_rows:
                    continue
                block = [c.to_numpy(zero_copy_only=False) for c in batch.columns]
                if not _plain(block, [c.null_count for c in batch.columns], last):
                    return None
                columns.append(block)
                last = float(block[0][-1])
    except (pa.ArrowException, UnicodeEncodeError, OSError):  # ArrowInvalid: a ValueError
        return None  # the cell-by-cell reader, on the file already open, has the last word
    return columns if columns.rows else None


_LO = np.array([BY_NAME[n].lo for n in COLUMN_NAMES])
_HI = np.array([BY_NAME[n].hi for n in COLUMN_NAMES])


def _plain(block: Sequence[np.ndarray], nulls: Sequence[int], last: float) -> bool:
    """Whether a block of columns holds what the format allows, blanks being null: a time
    in every row, increasing past ``last``; no NaN but the blanks (so no literal ``nan``);
    every value within its column's range (every range is finite, so no infinity either:
    a test holds the ranges to that)."""
    t = block[0]
    if nulls[0] or not t[0] > last:
        return False
    with np.errstate(invalid="ignore"):
        for a, n, lo, hi in zip(block, nulls, _LO, _HI, strict=True):
            if int(np.count_nonzero(np.isnan(a))) != n or (a < lo).any() or (a > hi).any():
                return False
    return len(t) < 2 or bool((np.diff(t) > 0).all())  # finite times now: no warning


def _slow_chunk(spath: str, chunk: list[str], first: int, prev: tuple[float, int] | None
                ) -> tuple[np.ndarray, tuple[float, int] | None]:
    """Cell by cell, with the csv module: every fault named by line and column."""
    ncol = len(COLUMN_NAMES)
    rows: list[list[float]] = []
    for k, line in enumerate(chunk):
        lineno = first + k
        if not line.strip():
            continue
        try:
            cells = next(csv.reader([line]))
        except csv.Error as e:  # a cell longer than the csv module's limit, a stray quote
            raise SignalsFormatError(spath, lineno, None,
                                     f"not a CSV row ({e}); expected {ncol} numbers") from None
        if len(cells) != ncol:
            raise SignalsFormatError(spath, lineno, None,
                                     f"expected {ncol} values, found {len(cells)}")
        row = []
        for name, cell in zip(COLUMN_NAMES, cells, strict=True):
            cell = cell.strip()
            if cell == "":
                if name == "time_s":
                    raise SignalsFormatError(spath, lineno, name, "time must not be blank")
                row.append(math.nan)
                continue
            try:
                v = float(cell)
            except ValueError:
                raise SignalsFormatError(spath, lineno, name,
                                         f"expected a number, got {cell!r}") from None
            if not math.isfinite(v):
                raise SignalsFormatError(spath, lineno, name,
                                         f"{cell!r} is not a finite number (leave unknown "
                                         "values blank)")
            col = BY_NAME[name]
            if not col.lo <= v <= col.hi:
                raise SignalsFormatError(
                    spath, lineno, name,
                    f"{v:g} {col.unit} is outside the plausible range "
                    f"[{col.lo:g}, {col.hi:g}] {col.unit} ({col.doc}); wrong unit?")
            row.append(v)
        if prev is not None and row[0] <= prev[0]:
            raise SignalsFormatError(
                spath, lineno, "time_s",
                f"time {row[0]:g} s is not after the previous row's {prev[0]:g} s "
                f"(line {prev[1]}); rows must be in strictly increasing time")
        rows.append(row)
        prev = (row[0], lineno)
    return np.array(rows, dtype=float).reshape(-1, ncol), prev


def _fmt(v: float) -> str:
    if math.isnan(v):
        return ""
    return f"{v:.6g}" if abs(v) >= 1e5 else f"{v:.6f}".rstrip("0").rstrip(".")


def iter_rows(table: SignalsTable) -> Iterator[str]:
    cols = [table.columns[n] for n in COLUMN_NAMES]
    for j in range(len(table)):
        yield ",".join(_fmt(float(c[j])) for c in cols)


def write_table(path: str | Path, table: SignalsTable) -> None:
    """Write ``table`` as ``shovel-signals/1`` (metadata lines, header, rows)."""
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        write_header(f, table.meta)
        write_rows(f, table)


def write_header(f: TextIO, meta: dict[str, str]) -> None:
    """The metadata lines and the column header (a streamed table then takes
    :func:`write_rows` once per part)."""
    for k, v in {"format": FORMAT_NAME, **meta}.items():
        f.write(f"# {k}: {v}\n")
    f.write(",".join(COLUMN_NAMES) + "\n")


def write_rows(f: TextIO, table: SignalsTable) -> None:
    for line in iter_rows(table):
        f.write(line + "\n")
