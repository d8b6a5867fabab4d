"""Every command with bad input answers one line naming what is wrong, and exits non-zero:
the matrix of ``bench/bad_input.py``, one test per command and case."""

from __future__ import annotations

import atexit
import logging
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import bad_input  # noqa: E402

_TMP = Path(tempfile.mkdtemp(prefix="shoveld-bad-input-"))
atexit.register(shutil.rmtree, _TMP, True)
CASES = bad_input.cases(bad_input.files(_TMP))


@pytest.mark.parametrize("command,case,argv", CASES,
                         ids=[f"{c}-{k}" for c, k, _ in CASES])
def test_bad_input_is_one_line(command: str, case: str, argv: list[str]) -> None:
    logging.disable(logging.CRITICAL)
    try:
        r = bad_input.run_case(command, case, argv)
    finally:
        logging.disable(logging.NOTSET)
    assert not r.traceback, r.traceback
    assert r.code not in (0, None), (r.code, r.stderr)
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1, r.stderr
