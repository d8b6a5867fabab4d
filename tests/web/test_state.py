"""What the pages say, computed from messages (``shoveld.web.state``)."""

from __future__ import annotations

import pytest

from shoveld.web.state import SILENT_AFTER_S, ScreenState, last_pass_hint, truck_warning


def test_last_pass_hint_tops_off_without_passing_110_percent() -> None:
    h = last_pass_hint(110_000.0, 136_000.0, [28_000.0, 30_000.0])
    assert h["kind"] == "last" and h["carry_kg"] == pytest.approx(26_000.0)
    assert h["max_kg"] == pytest.approx(1.1 * 136_000 - 110_000)
    assert "26.0 t" in h["text"] and "39.6 t" in h["text"]
    more = last_pass_hint(40_000.0, 136_000.0, [30_000.0] * 5)
    assert more["kind"] == "more" and more["passes_left"] == 4
    assert more["text"].startswith("4 passes left, about 24.0 t each")
    assert more["carry_kg"] * 4 == pytest.approx(96_000.0)
    assert last_pass_hint(137_000.0, 136_000.0, [30_000.0])["kind"] == "full"
    assert last_pass_hint(0.0, 136_000.0, [])["kind"] == "unknown"


def test_warnings_name_the_overload_and_only_a_closed_truck_is_under() -> None:
    assert truck_warning({"status": "over_120", "fill_pct": 123.0})["level"] == "alarm"
    assert "110" in truck_warning({"status": "over_110", "fill_pct": 112.0})["text"]
    assert truck_warning({"status": "under", "fill_pct": 34.0}) is None  # still loading
    assert truck_warning({"status": "under", "fill_pct": 34.0, "closed": True}) is not None


def test_a_shovel_not_heard_from_is_silent_and_shows_no_number() -> None:
    st = ScreenState()
    st.set_link("up")
    st.on_alive("s1", True)
    st.on_message("s1", "payload/live", {"payload_kg": 20000.0, "std_kg": 300.0,
                                         "valid": True, "phase": "swing"})
    st.on_message("s1", "truck", {"truck": 4, "passes": 2, "total_kg": 60000.0,
                                  "target_kg": 136000.0, "status": "under"})
    heard = st.heard["s1"]
    fresh = st.snapshot(now=heard + 0.5)["shovels"][0]
    assert fresh["valid"] and fresh["payload_kg"] == 20000.0 and not fresh["silent"]
    assert fresh["remaining_kg"] == pytest.approx(76000.0)
    old = st.snapshot(now=heard + SILENT_AFTER_S + 1.0)["shovels"][0]
    assert old["silent"] and not old["valid"] and old["payload_kg"] is None
    assert old["problems"][0].startswith("daemon: not heard for")
    st.on_alive("s1", False)
    gone = st.snapshot(now=heard + 0.5)["shovels"][0]
    assert gone["silent"] and "liveliness lost" in gone["problems"][0]


def test_a_closed_truck_counts_once_in_the_shift() -> None:
    st = ScreenState()
    st.on_message("s1", "truck", {"truck": 1, "passes": 4, "total_kg": 130000.0,
                                  "target_kg": 136000.0, "status": "ok"})
    st.on_message("s1", "truck", {"truck": 1, "passes": 4, "total_kg": 130000.0,
                                  "target_kg": 136000.0, "status": "ok", "closed": True})
    s = st.snapshot()["shovels"][0]
    assert s["truck"]["closed"] and s["hint"]["kind"] == "closed"
    assert s["shift"] == {"trucks": 1, "passes": 4, "kg": 130000.0}
    st.on_message("s1", "truck", {"truck": 2, "passes": 1, "total_kg": 30000.0,
                                  "target_kg": 136000.0, "status": "under"})
    assert st.snapshot()["shovels"][0]["shift"] == {"trucks": 2, "passes": 5, "kg": 160000.0}


def test_the_shift_comes_from_the_daemons_pass_log_when_it_says_so() -> None:
    """A screen started mid-shift shows the daemon's totals, not only the trucks it saw."""
    st = ScreenState()
    st.on_status("s1", {"shovel": "s1", "truck": {
        "truck": 9, "passes": 2, "total_kg": 60000.0, "target_kg": 136000.0,
        "status": "under", "shift": {"window_h": 12.0, "trucks": 8, "passes": 37,
                                     "kg": 1_050_000.0}}})
    assert st.snapshot()["shovels"][0]["shift"] == {"trucks": 9, "passes": 39,
                                                    "kg": 1_110_000.0}
    st.on_message("s1", "truck", {"truck": 9, "passes": 4, "total_kg": 130000.0,
                                  "target_kg": 136000.0, "status": "ok", "closed": True,
                                  "shift": {"trucks": 9, "passes": 41, "kg": 1_180_000.0}})
    assert st.snapshot()["shovels"][0]["shift"] == {"trucks": 9, "passes": 41,
                                                    "kg": 1_180_000.0}
