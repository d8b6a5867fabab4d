"""The screen's own Zenoh link on the cab page: when the router it connects through is
gone, the health strip says it once, as the screen's, before the shovel's problems."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from shoveld.web.browser import open_browser
from shoveld.web.server import ThreadedScreen
from shoveld.web.state import ScreenState
from tests.daemon.conftest import wait_for
from tests.web.test_panel_sizes import mid_truck, served

DOWN = "this screen cannot reach tls/10.20.0.2:7447 for 4 s: no shovel's messages can come"


@pytest.fixture
def state() -> ScreenState:
    return mid_truck()


@pytest.fixture
def page(state: ScreenState) -> Iterator[ThreadedScreen]:
    yield from served(state, ["s1"])


def test_the_cab_page_says_its_link_is_down_once(state: ScreenState,
                                                 page: ThreadedScreen) -> None:
    b = open_browser(1280, 800)

    def text(element_id: str) -> str:
        return str(b.find_element("id", element_id).text)

    def said() -> list[str]:
        """The strip's problems: whole in its title when the strip shows their heads,
        else as the strip shows them."""
        h = b.find_element("id", "health")
        title = h.get_attribute("title") or ""
        return title.split("\n") if title else str(h.text).split(" · ")

    try:
        b.get(page.url)
        assert wait_for(lambda: text("payload") == "31.2 t", 10.0)
        assert "zenoh" not in text("health")
        state.set_link("down", DOWN)
        assert wait_for(lambda: said()[0] == "zenoh: " + DOWN, 10.0), said()
        # said once: the shovel's copy of the link's words ("link: down ...") not beside it
        assert not [p for p in said() if "cannot reach" in p][1:], said()
        assert text("link").lower() == "link down"
        assert "bad" in (b.find_element("id", "health").get_attribute("class") or "")
        state.set_link("up", "tls/10.20.0.2:7447")
        assert wait_for(lambda: "zenoh" not in text("health") and text("link").lower() == "link up",
                        10.0), text("health")
    finally:
        b.quit()
