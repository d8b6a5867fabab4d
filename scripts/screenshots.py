"""Screenshots of the cab and office pages in their main states, for docs/screens/.

The pages are fed a fixed sequence of the daemon's messages (so the pictures are the
same every time) and shot in headless Chromium at the cab panel's 1280 x 800 (one also
at 1024 x 600).

    .venv/bin/python scripts/screenshots.py [--out docs/screens]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from shoveld.payload.trucks import Truck
from shoveld.web.browser import open_browser
from shoveld.web.server import ThreadedScreen
from shoveld.web.state import ScreenState

TARGET = 136000.0
RULE = {"window_h": 12.0, "trucks": 7, "mean_kg": 131800.0, "target_kg": TARGET,
        "mean_pct": 96.9, "over_110_pct": 0.0, "over_120": 0, "compliant": True}
NOT_WEIGHED = ("the crowd laser may not be on the handle: it had no reading for 1.0 s in this "
               "pass, and the pass does not fit the machine since (misfit 197, its usual "
               "0.84); something else may be in its beam")
JOINTS = {"handle_deg": 18.0, "crowd_m": 9.1, "boom_deg": 45.0, "swing_deg": 82.0,
          "invalid": []}


def truck(n: int, passes: list[float | None], closed: bool = False) -> dict[str, Any]:
    """A truck as the daemon sends it (``None``: a pass not weighed)."""
    t = Truck(n, TARGET, [{"payload_kg": p, "std_kg": 300.0, "valid": p is not None}
                          for p in passes])
    return {**t.as_dict(), "closed": closed, "rule_10_10_20": RULE}


def feed(st: ScreenState, shovel: str, done: list[list[float]], current: list[float | None],
         live: float | None, phase: str, problems: list[str],
         misfits: dict[int, float] | None = None) -> None:
    """One shovel's shift so far; ``misfits``: passes of the current truck (from 0) the
    daemon marked as not fitted by the model, with their misfit; a ``None`` in
    ``current``: a pass the engine did not weigh."""
    misfits = misfits or {}
    st.on_alive(shovel, True)
    n = 0
    for k, t in enumerate(done, start=1):
        for p in t:
            n += 1
            st.on_message(shovel, "pass", {"pass": n, "truck": k, "payload_kg": p,
                                           "std_kg": 300.0, "valid": True})
        st.on_message(shovel, "truck", truck(k, t, closed=True))
    k = len(done) + 1
    st.on_message(shovel, "truck", truck(k, []))
    for i, p in enumerate(current):
        n += 1
        st.on_message(shovel, "pass", {"pass": n, "truck": k, "payload_kg": p,
                                       "std_kg": None if p is None else 300.0,
                                       "valid": p is not None,
                                       "reason": "" if p is not None else NOT_WEIGHED,
                                       "misfit": misfits.get(i, 0.8),
                                       "misfit_high": i in misfits})
        st.on_message(shovel, "truck", truck(k, current[:i + 1]))
    st.on_message(shovel, "joints", JOINTS)
    st.on_message(shovel, "payload/live", {"payload_kg": live, "std_kg": 310.0,
                                           "valid": live is not None, "phase": phase})
    st.on_message(shovel, "health", {"problems": problems, "ok": not problems})


def shoot(name: str, st: ScreenState, out: Path, path: str = "", night: bool = False,
          size: tuple[int, int] = (1280, 800)) -> None:
    page = ThreadedScreen(st)
    b = open_browser(*size)
    try:
        b.get(page.url + path)
        if night:
            b.execute_script("localStorage.setItem('shoveld-theme', 'night')")
            b.refresh()
        time.sleep(1.0)
        # The pictures show a shovel that is talking (but the one the office shows silent).
        now = time.monotonic()
        for name_, t in st.heard.items():
            if now - t < 5.0:
                st.heard[name_] = now
        st.set_link(st.link, st.link_detail)
        time.sleep(0.5)
        b.save_screenshot(str(out / f"{name}.png"))
    finally:
        b.quit()
        page.close()
    print(f"wrote {out / name}.png")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="docs/screens")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    done = [[33100.0, 34200.0, 31800.0, 33500.0], [32900.0, 34800.0, 33300.0, 32000.0]]
    st = ScreenState()
    st.set_link("up", "tcp/127.0.0.1:7447")
    feed(st, "ph4100-07", done, [33400.0, 32700.0, 34100.0], 26800.0, "swing", [])
    shoot("cab-loading", st, out)
    shoot("cab-night", st, out, night=True)
    st = ScreenState()
    st.set_link("up", "tcp/127.0.0.1:7447")
    feed(st, "ph4100-07", done, [33400.0, 34700.0, 34100.0, 34900.0, 20100.0], None, "return",
         [])
    shoot("cab-overload", st, out)
    shoot("cab-1024x600", st, out, size=(1024, 600))
    st = ScreenState()
    st.set_link("up", "tcp/127.0.0.1:7447")
    feed(st, "ph4100-07", done, [33400.0], None, "lift",
         ["laser: no reading for 3.0 s", "loop: 14 overruns in the last 100 ticks"])
    shoot("cab-sensor-missing", st, out)
    st = ScreenState()
    st.set_link("up", "tcp/127.0.0.1:7447")
    feed(st, "ph4100-07", done, [35100.0, 38600.0, 35300.0], 34900.0, "swing",
         ["payload: the empty dipper weighs +1.6 t on its returns (median of the last 5): "
          "the calibration or the model is off, the passes may be too; weigh a known load"],
         misfits={1: 6.2})
    shoot("cab-doubtful", st, out)
    st = ScreenState()
    st.set_link("up", "tcp/127.0.0.1:7447")
    feed(st, "ph4100-07", done, [33400.0, None, 34100.0], 30600.0, "swing", [])
    shoot("cab-not-weighed", st, out)
    st = ScreenState()
    st.set_link("up", "tcp/10.20.0.5:7447 (site router)")
    feed(st, "ph4100-07", done, [33400.0, 32700.0], 30100.0, "lift", [])
    feed(st, "ph4100-09", done[:1], [29800.0], None, "dig", [])
    feed(st, "wa1200-02", [], [21000.0, 22500.0], None, "return", ["mti: disconnected"])
    st.heard["wa1200-02"] -= 12.0  # went quiet 12 s ago
    shoot("office", st, out, "office")


if __name__ == "__main__":
    main()
