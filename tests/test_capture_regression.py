"""gpsd-style regression: every committed capture replays to its expected passes.

See ``hil_fixtures/regress.py``: each capture must reproduce the passes of its last
rebuild to the kilogram (replay is deterministic) and stay within 1 % of rated load
of both the true payload and the offline estimate of the table it was played from.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from hil_fixtures.regress import captures, check


@pytest.mark.parametrize("capture", captures(), ids=lambda p: p.name)
def test_capture_replays_to_its_expected_passes(capture: Path) -> None:
    assert check(capture) == []


def test_there_are_captures_of_both_mti_transports() -> None:
    import json

    kinds = set()
    for cap in captures():
        manifest = json.loads((cap / "manifest.json").read_text())
        devs = manifest["devices"]
        kinds |= {d["kind"] for d in (devs.values() if isinstance(devs, dict) else devs)}
    assert {"mti_serial", "mti_can", "ar4000", "modbus_tcp", "modbus_rtu"} <= kinds
