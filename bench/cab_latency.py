"""Latency from a pass published (right after the daemon commits it) to it shown on the
cab page, measured in a real browser.

A Zenoh peer on loopback publishes ``pass`` messages the way the daemon does; the cab
page server (``shoveld.web``) subscribes as a cab display; headless Chromium shows the
page, whose script notes the wall time each pass first appears in the table. Both clocks
are this machine's.

    .venv/bin/python bench/cab_latency.py [--passes 200] [--interval 0.1]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from hil_fixtures.net import free_port


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--passes", type=int, default=200)
    ap.add_argument("--interval", type=float, default=0.1, help="seconds between passes")
    args = ap.parse_args()
    import zenoh

    from shoveld.cli.cab import TOPICS, CabClient
    from shoveld.daemon.publisher import zenoh_config
    from shoveld.web.browser import open_browser
    from shoveld.web.server import ThreadedScreen
    from shoveld.web.state import ScreenState

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    pub_session = zenoh.open(zenoh_config("peer", [endpoint]))
    state = ScreenState()
    cab = CabClient(state, [endpoint], "client", "b1", topics=TOPICS | {"joints"})
    state.set_link("up", endpoint)
    page = ThreadedScreen(state)
    browser = open_browser()
    sent: dict[int, float] = {}
    try:
        browser.get(page.url)
        time.sleep(1.0)
        key = "shovel/b1/"
        pub_session.put(key + "truck", json.dumps(
            {"truck": 1, "passes": 0, "total_kg": 0.0, "target_kg": 1e12, "status": "under"}))
        time.sleep(0.5)
        for n in range(1, args.passes + 1):
            msg = {"pass": n, "truck": 1, "payload_kg": 30000.0, "std_kg": 200.0,
                   "valid": True, "reason": "", "start": time.time() - 20, "end": time.time()}
            sent[n] = time.time() * 1000.0
            pub_session.put(key + "pass", json.dumps(msg))
            time.sleep(args.interval)
        time.sleep(1.0)
        shown = browser.execute_script("return screen.shown")
    finally:
        browser.quit()
        page.close()
        cab.close()
        pub_session.close()
    lat = sorted(shown[str(n)] - sent[n] for n in sent if str(n) in shown)
    missing = len(sent) - len(lat)
    if not lat:
        raise SystemExit("no pass reached the page")
    p99 = lat[min(len(lat) - 1, int(round(0.99 * (len(lat) - 1))))]
    print(f"passes {len(sent)}, shown {len(lat)}, missing {missing}")
    print(f"latency publish -> on the page: p50 {statistics.median(lat):.0f} ms, "
          f"p99 {p99:.0f} ms, max {lat[-1]:.0f} ms")


if __name__ == "__main__":
    main()
