"""The pages' own words for counts (``screen.n`` in common.js): the first truck of a
shift on the cab and office pages, and a fleet of one, read "1 truck", "1 pass",
"1 shovel", as the Python side's ``shoveld.words.n_of`` writes them."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from shoveld.web.browser import open_browser
from shoveld.web.server import ThreadedScreen
from shoveld.web.state import ScreenState
from tests.daemon.conftest import wait_for
from tests.web.test_panel_sizes import served


@pytest.fixture(scope="module")
def first_truck() -> Iterator[ThreadedScreen]:
    """One shovel whose first truck of the shift was sent off after one pass."""
    st = ScreenState()
    st.set_link("up", "test")
    st.on_alive("s1", True)
    st.on_message("s1", "pass", {"pass": 1, "truck": 1, "payload_kg": 138000.0,
                                 "std_kg": 300.0, "valid": True})
    st.on_message("s1", "truck", {"truck": 1, "passes": 1, "total_kg": 138000.0,
                                  "target_kg": 136000.0, "fill_pct": 101.5, "status": "ok",
                                  "closed": True, "rule_10_10_20": {
                                      "trucks": 1, "mean_pct": 101.5, "over_110_pct": 0.0,
                                      "over_120": 0, "compliant": True}})
    yield from served(st, ["s1"])


def test_one_truck_one_pass_one_shovel(first_truck: ThreadedScreen) -> None:
    b = open_browser(1280, 800)

    def text(element_id: str) -> str:
        """The words the page wrote (textContent: the office's labels are capitals only
        by style)."""
        return b.execute_script(
            "return document.getElementById(arguments[0]).textContent", element_id)

    try:
        b.get(first_truck.url)
        assert wait_for(lambda: text("shift").startswith("1 truck, mean 101.5 %"), 10.0), \
            text("shift")
        b.get(first_truck.url + "office")
        assert wait_for(lambda: text("summary") == "1 shovel, 0 silent", 10.0), \
            text("summary")
        assert "this shift: 1 pass, 138.0 t in 1 truck" in text("cards"), text("cards")
    finally:
        b.quit()
