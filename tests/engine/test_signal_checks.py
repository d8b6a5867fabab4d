"""A signals table whose crowd extension jumps further than a handle moves is named by
every command that reads one (estimate, calibrate, diagnose): the daemon's laser driver
drops such lines; a table from another logger may hold them."""

from __future__ import annotations

import numpy as np
import pytest

from shoveld.cli.common import warn_crowd_jumps
from shoveld.signals.checks import crowd_jumps
from shoveld.sim.scenario import SimResult


def test_a_stray_crowd_value_and_the_return_from_it_are_named(
        cycles: SimResult, capsys: pytest.CaptureFixture[str]) -> None:
    clean = cycles.table
    assert len(crowd_jumps(clean)) == 0  # the simulated handle never moves that fast
    warn_crowd_jumps(clean)
    assert capsys.readouterr().err == ""
    table = clean.slice(np.ones(len(clean), dtype=bool))
    crowd = table["crowd_m"]
    for row, off in ((1000, 2.0), (2000, -0.6), (3000, 0.2)):
        crowd[row] += off
    crowd[2500] = np.nan  # a blank cell is skipped, not a jump
    j = 2600 + int(np.argmax(np.abs(np.diff(clean["crowd_m"][2599:2900]))))
    table.time[j] = table.time[j - 1]  # nor is a repeated time stamp while it moves
    assert abs(crowd[j] - crowd[j - 1]) > 0.01
    # a value held for 10 rows (a slower logger) where the handle moves fastest, then the
    # handle where it is: what it moved in the meantime, not a jump
    k = 3500 + int(np.argmax(np.abs(np.diff(clean["crowd_m"][3500:]))))
    crowd[k - 10:k] = crowd[k - 10]
    assert abs(crowd[k] - crowd[k - 1]) > 3.0 * 0.02 + 0.01  # more than one row allows
    assert crowd_jumps(table).tolist() == [1000, 1001, 2000, 2001, 3000, 3001]
    table.source = "other-logger.csv"
    warn_crowd_jumps(table)
    err = capsys.readouterr().err.splitlines()
    assert err == ["shoveld: warning: other-logger.csv: crowd_m moves further than "
                   "the handle can (3 m/s) at 6 rows, the first at time_s "
                   f"{table.time[1000]:g}: a laser return off something else in the beam? "
                   "They are used as they are"]
