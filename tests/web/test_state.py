"""What the pages say, computed from messages (``shoveld.web.state``)."""

from __future__ import annotations

import pytest

from shoveld.web.state import (
    SILENT_AFTER_S,
    ScreenState,
    doubtful_note,
    last_pass_hint,
    truck_warning,
)


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
    alarm = truck_warning({"status": "over_120", "fill_pct": 123.0})
    assert alarm is not None and alarm["level"] == "alarm"
    warn = truck_warning({"status": "over_110", "fill_pct": 112.0})
    assert warn is not None and "110" in warn["text"]
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
    assert s["shift"] == {"trucks": 1, "passes": 4, "kg": 130000.0, "not_weighed": 0,
                          "misfit_high": None}
    st.on_message("s1", "truck", {"truck": 2, "passes": 1, "total_kg": 30000.0,
                                  "target_kg": 136000.0, "status": "under"})
    assert st.snapshot()["shovels"][0]["shift"] == {"trucks": 2, "passes": 5, "kg": 160000.0,
                                                    "not_weighed": 0, "misfit_high": None}


def test_the_shift_comes_from_the_daemons_pass_log_when_it_says_so() -> None:
    """A screen started mid-shift shows the daemon's totals, not only the trucks it saw."""
    st = ScreenState()
    st.on_status("s1", {"shovel": "s1", "truck": {
        "truck": 9, "passes": 2, "total_kg": 60000.0, "target_kg": 136000.0,
        "status": "under", "shift": {"window_h": 12.0, "trucks": 8, "passes": 37,
                                     "kg": 1_050_000.0}}})
    assert st.snapshot()["shovels"][0]["shift"] == {"trucks": 9, "passes": 39,
                                                    "kg": 1_110_000.0, "not_weighed": 0,
                                                    "misfit_high": None}
    st.on_message("s1", "truck", {"truck": 9, "passes": 4, "total_kg": 130000.0,
                                  "target_kg": 136000.0, "status": "ok", "closed": True,
                                  "shift": {"trucks": 9, "passes": 41, "kg": 1_180_000.0}})
    assert st.snapshot()["shovels"][0]["shift"] == {"trucks": 9, "passes": 41,
                                                    "kg": 1_180_000.0, "not_weighed": 0,
                                                    "misfit_high": None}


def test_passes_the_model_did_not_fit_are_marked_by_the_daemons_word() -> None:
    """The daemon marks a pass ``misfit_high`` by its own level; the cab marks that pass
    and says why under the list, numbered within the truck as the list is. A pass not
    weighed is not marked (it says why already), nor one from a daemon that sends no mark."""
    st = ScreenState()
    st.on_alive("s1", True)
    st.on_message("s1", "truck", {"truck": 2, "passes": 0, "total_kg": 0.0,
                                  "target_kg": 136000.0, "fill_pct": 0.0, "status": "under"})
    marks = [(False, 0.8), (True, 6.24), (False, None), (True, 41.0), (False, 3.5)]
    for k, (high, misfit) in enumerate(marks):
        st.on_message("s1", "pass", {"pass": 20 + k, "truck": 2, "payload_kg": 30000.0,
                                     "std_kg": 200.0, "valid": k != 3, "misfit": misfit,
                                     "misfit_high": high, "reason": "" if k != 3 else "x"})
    snap = st.snapshot()["shovels"][0]
    assert [p["misfit_high"] for p in snap["passes"]] == [m for m, _ in marks]
    # pass 4 of the truck was not weighed: only pass 2 is doubtful
    assert snap["doubt"] == "? pass 2: the model did not fit it (misfit 6.2); its weight may be off"
    st.on_message("s1", "pass", {"pass": 25, "truck": 2, "payload_kg": 31000.0,
                                 "std_kg": 200.0, "valid": True, "misfit": 9.0,
                                 "misfit_high": True})
    assert st.snapshot()["shovels"][0]["doubt"] == (
        "? passes 2 and 6: the model did not fit them; their weights may be off")
    # a daemon older than the mark sends misfit alone: the screen does not judge it
    assert doubtful_note([{"valid": True, "misfit": 50.0}]) is None
    assert doubtful_note([{"valid": True, "misfit_high": True}]) == (
        "? pass 1: the model did not fit it; its weight may be off")
    # the next truck starts clean
    st.on_message("s1", "truck", {"truck": 3, "passes": 0, "total_kg": 0.0,
                                  "target_kg": 136000.0, "fill_pct": 0.0, "status": "under"})
    assert st.snapshot()["shovels"][0]["doubt"] is None


def test_the_shift_counts_the_passes_the_model_did_not_fit() -> None:
    """The daemon counts its closed trucks' marked passes from the pass log; the screen
    adds the open truck's weighed ones (a pass not weighed is not marked)."""
    st = ScreenState()
    st.on_message("s1", "truck", {"truck": 9, "passes": 0, "total_kg": 0.0,
                                  "target_kg": 136000.0, "status": "under",
                                  "shift": {"trucks": 8, "passes": 37, "kg": 1_050_000.0,
                                            "misfit_high": 2}})
    for n, (valid, high) in enumerate([(True, True), (False, True), (True, False)], 40):
        st.on_message("s1", "pass", {"pass": n, "truck": 9, "payload_kg": 30000.0,
                                     "std_kg": 200.0, "valid": valid, "misfit": 5.0,
                                     "misfit_high": high})
    assert st.snapshot()["shovels"][0]["shift"]["misfit_high"] == 3


def test_a_pass_not_weighed_is_not_taken_for_an_empty_one() -> None:
    """A truck with a pass the engine did not weigh has a load known only from below. The
    last-pass hint counts that pass as the shovel's typical one and says so, where leaving
    it out would ask the operator for a pass more than the truck can take; with no typical
    pass it says the load is not known. The warning, the closed trucks and the shift say
    how many were not weighed."""
    st = ScreenState()
    st.on_alive("s1", True)
    shift = {"trucks": 8, "passes": 37, "kg": 1_050_000.0, "not_weighed": 2,
             "misfit_high": 0}
    st.on_message("s1", "truck", {"truck": 9, "passes": 0, "total_kg": 0.0,
                                  "target_kg": 136000.0, "status": "under", "shift": shift})
    for n, valid in enumerate([True, True, False], 40):
        st.on_message("s1", "pass", {"pass": n, "truck": 9, "valid": valid,
                                     "payload_kg": 34000.0 if valid else None,
                                     "std_kg": 200.0 if valid else None,
                                     "reason": "" if valid else "the crowd laser may not be"})
    st.on_message("s1", "truck", {"truck": 9, "passes": 3, "total_kg": 68000.0,
                                  "target_kg": 136000.0, "fill_pct": 50.0,
                                  "status": "incomplete", "invalid_passes": 1,
                                  "shift": shift})
    s = st.snapshot()["shovels"][0]
    # 68 t weighed + one typical 34 t pass not weighed: one pass of 34 t left, not two
    assert s["hint"]["kind"] == "last" and s["remaining_kg"] == pytest.approx(34000.0)
    assert s["hint"]["text"] == ("Last pass: carry 34.0 t (at most 47.6 t), "
                                 "counting the pass not weighed as 34.0 t")
    assert s["warning"] == {"level": "warn", "text": "1 pass not weighed: at least 50.0 % loaded"}
    assert s["shift"]["not_weighed"] == 3  # the daemon's 2 and the open truck's 1
    st.on_message("s1", "truck", {"truck": 9, "passes": 3, "total_kg": 68000.0,
                                  "target_kg": 136000.0, "fill_pct": 50.0, "closed": True,
                                  "status": "incomplete", "invalid_passes": 1})
    s = st.snapshot()["shovels"][0]
    assert s["closed"][0]["invalid_passes"] == 1 and s["closed"][0]["status"] == "incomplete"
    assert s["warning"]["text"] == "Sent off with 1 pass not weighed: at least 50.0 % of target"
    # a shovel with no weighed pass yet: the hint does not guess
    hint = last_pass_hint(0.0, 136000.0, [], not_weighed=1)
    assert hint["kind"] == "unknown" and hint["remaining_kg"] is None
    assert hint["text"] == "1 pass not weighed: the truck's load is not known"
    # full by its weighed passes alone: full, whatever the pass not weighed carried
    full = last_pass_hint(140000.0, 136000.0, [], not_weighed=1)
    assert full["kind"] == "full" and full["remaining_kg"] == -4000.0
    two = last_pass_hint(20000.0, 136000.0, [30000.0], not_weighed=2)
    assert two["text"] == "2 passes left, about 28.0 t each, counting the passes not " \
                          "weighed as 30.0 t each"


def test_the_live_number_carries_the_crowds_doubt_while_it_is_a_number() -> None:
    """The daemon's ``crowd_doubt`` on a live estimate reaches the pages with the number;
    with no number (not valid, or the shovel silent) there is nothing to mark."""
    st = ScreenState()
    st.on_alive("s1", True)
    st.on_message("s1", "payload/live", {"payload_kg": 30500.0, "std_kg": 300.0,
                                         "valid": True, "phase": "lift",
                                         "crowd_doubt": "had no reading for 1.0 s"})
    heard = st.heard["s1"]
    s = st.snapshot(now=heard + 0.5)["shovels"][0]
    assert s["valid"] and s["crowd_doubt"] == "had no reading for 1.0 s"
    assert st.snapshot(now=heard + SILENT_AFTER_S + 1.0)["shovels"][0]["crowd_doubt"] is None
    st.on_message("s1", "payload/live", {"payload_kg": None, "std_kg": None, "valid": False,
                                         "phase": "dump",
                                         "crowd_doubt": "had no reading for 1.0 s"})
    assert st.snapshot()["shovels"][0]["crowd_doubt"] is None
    # a daemon older than the field sends none: nothing is marked
    st.on_message("s1", "payload/live", {"payload_kg": 30500.0, "std_kg": 300.0,
                                         "valid": True, "phase": "swing"})
    assert st.snapshot()["shovels"][0]["crowd_doubt"] is None


def test_the_messages_refused_from_a_shovel_are_counted_on_the_page() -> None:
    """A message of another shape is refused (``shoveld.daemon.messages``); the page says
    how many, for the operator or mine IT who looks at it, and redraws when one comes."""
    changes: list[int] = []
    st = ScreenState(on_change=lambda: changes.append(1))
    st.set_link("up")
    st.on_alive("s1", True)
    st.on_message("s1", "payload/live", {"payload_kg": 20000.0, "std_kg": 300.0,
                                         "valid": True, "phase": "swing"})
    assert not [p for p in st.snapshot()["shovels"][0]["problems"] if "refused" in p]
    n = len(changes)
    for _ in range(3):
        st.on_bad_message("s1", "pass", "key 'payload_kg' is 'heavy', not a finite number")
    assert len(changes) == n + 3
    problems = st.snapshot()["shovels"][0]["problems"]
    assert "screen: 3 messages from this shovel refused (fields of another kind: another " \
           "version of the daemon?)" in problems
