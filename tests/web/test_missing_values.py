"""The cab and office pages when a message leaves a value out (null or absent: another
version of the daemon, or a value it has not): the page says "-" or leaves the value
off, never a number it was not sent ("0.0" where JavaScript turns null into 0) nor
"NaN", "null" or "undefined"."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest

from shoveld.web.browser import open_browser
from shoveld.web.server import ThreadedScreen
from shoveld.web.state import ScreenState
from tests.daemon.conftest import wait_for
from tests.web.test_panel_sizes import served

LIVE = {"payload_kg": 31234.0, "std_kg": None, "valid": True, "phase": "swing"}


def sparse_state() -> ScreenState:
    """Shovel s1: truck 4 sent off without its total, fill or 10/10/20 figures; truck 5
    under way with a pass whose spread is null and one whose payload is."""
    st = ScreenState()
    st.set_link("up", "test")
    st.on_alive("s1", True)
    st.on_message("s1", "truck", {"truck": 4, "passes": 2, "total_kg": None, "fill_pct": None,
                                  "target_kg": 136000.0, "status": "under", "closed": True,
                                  "rule_10_10_20": {"trucks": 1}})
    st.on_message("s1", "truck", {"truck": 5, "passes": 2, "total_kg": 62000.0,
                                  "target_kg": 136000.0, "fill_pct": 45.6, "status": "under"})
    st.on_message("s1", "pass", {"pass": 1, "truck": 5, "payload_kg": 31000.0,
                                 "std_kg": None, "valid": True, "end": time.time()})
    st.on_message("s1", "pass", {"pass": 2, "truck": 5, "payload_kg": None, "std_kg": 120.0,
                                 "valid": True, "end": time.time()})
    return st


@pytest.fixture(scope="module")
def page() -> Iterator[ThreadedScreen]:
    """:func:`sparse_state` served, the shovel heard from every half second with a live
    payload sent without its spread."""
    yield from served(sparse_state(), ["s1"], live=LIVE)


def cells(b: Any, body_id: str) -> list[list[str]]:
    """The text of each cell of each row of a table body (``b``: the Selenium driver)."""
    return b.execute_script(
        "return [...document.getElementById(arguments[0]).rows].map("
        "r => [...r.cells].map(c => c.textContent))", body_id)


def test_the_cab_page_says_a_value_left_out_is_missing(page: ThreadedScreen) -> None:
    b = open_browser()
    try:
        b.get(page.url)
        assert wait_for(lambda: b.find_element("id", "payload").text == "31.2 t", 10.0)
        assert b.find_element("id", "payload-std").text == ""  # no spread sent: none shown
        assert wait_for(lambda: len(cells(b, "passes")) == 2, 5.0)
        assert cells(b, "passes") == [["1", "31.0", "-"], ["2", "-", "0.1"]]
        trucks = cells(b, "trucks")
        assert trucks[0][:4] == ["4", "2", "-", "- %"], trucks
        shift = b.find_element("id", "shift").text
        assert shift.startswith("1 truck, mean - % of target, - % over 110 %, 0 over 120 %"), \
            shift
        text = b.find_element("tag name", "body").text
        assert not [w for w in ("NaN", "null", "undefined") if w in text], text
    finally:
        b.quit()


def test_the_office_page_leaves_out_a_spread_it_was_not_sent(page: ThreadedScreen) -> None:
    b = open_browser()
    try:
        b.get(page.url + "office")
        assert wait_for(lambda: "31.2 t" in b.find_element("tag name", "body").text, 10.0)
        text = b.find_element("tag name", "body").text
        assert "31.2 t ±" not in text, text
        assert not [w for w in ("NaN", "null", "undefined") if w in text], text
    finally:
        b.quit()
