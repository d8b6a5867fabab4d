"""Helpers shared by subcommands: reading tables and params with one-line errors.

The readers import numpy and the model when called, not when ``shoveld --help`` (which
imports every subcommand's module to list it) loads this file.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from shoveld.cli import CliError

if TYPE_CHECKING:
    from shoveld.model.params import ModelParams
    from shoveld.signals.table import SignalsTable


def read_tables(paths: list[str]) -> list[SignalsTable]:
    from shoveld.signals.table import SignalsFormatError, read_table

    out = []
    for p in paths:
        try:
            out.append(read_table(p))
        except SignalsFormatError as e:
            raise CliError(str(e)) from None
        warn_crowd_jumps(out[-1])
    return out


def warn_crowd_jumps(table: SignalsTable) -> None:
    """One line on stderr if the table's crowd extension jumps further than a handle moves
    (a laser return off something else: the daemon's driver drops those, a table from
    another logger may hold them); the rows are used as they are."""
    from shoveld.installation import CROWD_SPEED_MAX_MPS
    from shoveld.signals.checks import crowd_jumps
    from shoveld.words import n_of

    rows = crowd_jumps(table)
    if len(rows):
        print(f"shoveld: warning: {table.source}: crowd_m moves further than the handle can "
              f"({CROWD_SPEED_MAX_MPS:g} m/s) at {n_of(len(rows), 'row', 'rows')}, the first "
              f"at time_s {table.time[rows[0]]:g}: a laser return off something else in the "
              "beam? They are used as they are", file=sys.stderr)


def read_params(path: str) -> ModelParams:
    from shoveld.model.params import ParamsFileError, load_params

    try:
        return load_params(path)
    except ParamsFileError as e:
        raise CliError(str(e)) from None


def parse_effects(text: str | None) -> list[str]:
    """'a,b' -> ['a', 'b'] (blank entries dropped)."""
    return [e.strip() for e in (text or "").split(",") if e.strip()]


def one_blas_thread() -> None:
    """Tell numpy's OpenBLAS to start no worker threads, before numpy is imported (a
    setting read once, when the library loads; one already set is kept).

    The daemon's arrays are a few rows (3x3 joint filters, 10-row payload blocks): far
    below the sizes at which OpenBLAS splits work between threads, so its threads never
    run, but starting them was 40-60 ms of numpy's import on this 2-core machine
    (90-160 ms against 60-90 ms) - a tenth of ``shoveld replay --fast`` on a 103 s
    capture. Every event of the engine is the same with one thread or the default
    (docs/daemon.md, the seventh session's section)."""
    import os

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def check_output(path: str, *, folder: bool = False) -> None:
    """Refuse, before any work, an output the command could not write at its end (a
    calibration or a diagnosis of hours of data is minutes of work to lose): a file in a
    folder that does not exist or cannot be written, a file that is a folder, a folder
    that is a file. A ``folder`` output is made with its parents, so its nearest existing
    one must be a writable folder. The words are those of a late failure's line."""
    import errno
    import os

    p = os.path.abspath(path)
    if folder:
        if os.path.exists(p) and not os.path.isdir(p):
            raise CliError(f"{path}: {os.strerror(errno.ENOTDIR)} (a file is there; "
                           "expected a folder)")
        base = p
        while not os.path.exists(base):
            base = os.path.dirname(base)
        if not os.path.isdir(base):
            raise CliError(f"{path}: {os.strerror(errno.ENOTDIR)} ({base} is a file)")
    else:
        if os.path.isdir(p):
            raise CliError(f"{path}: {os.strerror(errno.EISDIR)}")
        base = os.path.dirname(p)
        if not os.path.isdir(base):
            raise CliError(f"{path}: {os.strerror(errno.ENOENT)} (the folder "
                           f"{os.path.dirname(path) or '.'} does not exist)")
        if os.path.exists(p) and not os.access(p, os.W_OK):
            raise CliError(f"{path}: {os.strerror(errno.EACCES)}")
    if not os.access(base, os.W_OK | os.X_OK):
        raise CliError(f"{path}: {os.strerror(errno.EACCES)} (the folder {base} is not "
                       "writable)")


def refuse_repeats(paths: list[str]) -> None:
    """The same data given twice would count twice: a calibration's standard errors
    shrink as if there were one more trial (Md's from 110 to 94 kg with a trial given
    twice), an estimate lists every pass twice. Refused: one file by two names (a
    shell glob and a name, a link) or two files with the same bytes (a copy)."""
    import hashlib
    import os

    first: dict[tuple[int, int], str] = {}
    by_size: dict[int, list[str]] = {}
    for p in paths:
        try:
            st = os.stat(p)
        except OSError:
            continue  # the reader names it
        key = (st.st_dev, st.st_ino)
        if key in first:
            also = "" if first[key] == p else f" (as {first[key]} too)"
            raise CliError(f"{p}: given twice{also}: its data would count twice")
        first[key] = p
        by_size.setdefault(st.st_size, []).append(p)
    for same_size in by_size.values():
        if len(same_size) < 2:
            continue
        digests: dict[str, str] = {}
        for p in same_size:
            try:
                with open(p, "rb") as f:
                    d = hashlib.file_digest(f, "sha1").hexdigest()
            except OSError:
                continue
            if d in digests:
                raise CliError(f"{p}: the same data as {digests[d]} (a copy): its data "
                               "would count twice")
            digests[d] = p
