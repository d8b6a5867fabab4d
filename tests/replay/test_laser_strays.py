"""Stray laser returns (something else in the beam) in a replayed capture: the daemon's
passes stay those of the clean capture, which they do not without the driver's rule."""

from __future__ import annotations

import random
import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import laser_strays  # noqa: E402


@pytest.fixture(scope="module")
def base() -> dict[str, Any]:
    """The clean capture replayed once for the module."""
    return laser_strays.replay(laser_strays.CAPTURE)


@pytest.fixture(scope="module")
def clean(base: dict[str, Any]) -> dict[int, float]:
    return dict(base["passes"])


@pytest.mark.parametrize("rule", [True, False], ids=["rule", "no-rule"])
def test_two_percent_stray_lines(tmp_path: Path, clean: dict[int, float], rule: bool) -> None:
    cap = laser_strays.stray_capture(tmp_path / "c", 0.02, 3, rule)
    got = laser_strays.replay(cap)
    assert len(clean) == 3 and sorted(dict(got["passes"])) == sorted(clean)
    assert all(kg is not None for _, kg in got["passes"])  # every pass valid
    err = max(abs(kg - clean[no]) for no, kg in got["passes"])
    if rule:  # each stray costs its ticks' updates, no more (0.1 % of a pass's payload)
        assert got["jumps"] >= 50 and err < 0.001 * min(clean.values())
    else:  # the bench's "before": the strays are taken for the crowd, tonnes off
        assert got["jumps"] == 0 and err > 1000.0


@pytest.mark.parametrize("other_target_s", [None, 0.1], ids=["default", "taken-at-once"])
def test_something_that_stays_in_the_beam_for_a_second(
        tmp_path: Path, base: dict[str, Any], clean: dict[int, float],
        other_target_s: float | None) -> None:
    """A second of something else in the beam in each pass's lift and swing: refused for
    the whole second by default (its ticks are not used, the passes stay within 0.3 % of
    the clean ones); taken once it has held for 0.1 s (as the driver did until
    2026-11-29 after five samples; it moved a pass by tonnes), the laser changes target
    twice in each pass, and no pass is weighed."""
    blocks = laser_strays.pass_blocks(base["spans"], 1.0, random.Random(4))
    laser = None if other_target_s is None else {"other_target_s": other_target_s}
    got = laser_strays.replay(laser_strays.stray_capture(tmp_path / "c", 0.0, 4, True, blocks,
                                                         laser))
    assert sorted(dict(got["passes"])) == sorted(clean)
    if other_target_s is None:  # about 50 lines a block, each refused
        assert all(kg is not None for _, kg in got["passes"])
        err = max(abs(kg - clean[no]) for no, kg in got["passes"])
        assert got["jumps"] >= 3 * 45 and err < 0.003 * min(clean.values())
    else:
        assert got["jumps"] < 3 * 20
        assert all(kg is None for _, kg in got["passes"])
        assert all("laser changed target" in why for why in got["reasons"].values())


def test_something_lodged_in_the_beam_after_a_pass(tmp_path: Path, base: dict[str, Any],
                                                   clean: dict[int, float]) -> None:
    """Something lodged in the beam 1 s after pass 1's dump, 1.5 m short of the handle,
    to the end: the driver takes it as its target after ``other_target_s`` (here as pass
    2 begins), and the laser reads it from then on. Pass 2 is not weighed for the change
    of target in it, pass 3 for a crowd that stood still; pass 1 is as in the clean
    capture."""
    end1 = base["spans"][0][2]  # pass 1's dump, capture seconds
    got = laser_strays.replay(laser_strays.stray_capture(tmp_path / "c", 0.0, 5, True,
                                                         lodged=(end1 + 1.0, -1500)))
    assert got["passes"] == [(1, clean[1]), (2, None), (3, None)]
    assert got["reasons"][2].startswith("the crowd laser changed target")
    assert got["reasons"][3].startswith("the crowd moved 0.00 m")


def test_something_that_comes_into_the_beam_while_the_laser_is_down(
        tmp_path: Path, base: dict[str, Any], clean: dict[int, float]) -> None:
    """The laser's stream cut for 2 s in pass 2's lift and swing (the driver goes silent
    and reconnects), and something on the handle, 1.5 m short of its target and moving
    with it, from the cut to the end. After a reconnect's second of silence the handle's
    reach (3 m/s) covers the thing, which the driver takes uncounted (docs/drivers-ar4000.md,
    "A reconnect keeps the handle's reach"); a meter that cannot tell the thing from the
    handle should not weigh passes 2 and 3 on it: each is either not weighed or within
    1 % of the clean capture's. Until the thirty-third session both were weighed tonnes
    off; the engine's crowd in doubt (``CrowdDoubt``) now refuses them: the laser lost the
    handle, and the passes after it do not fit the machine as pass 1 did."""
    _, a, b = base["spans"][1]
    end = base["spans"][-1][2] + 100.0
    t0 = a + 0.5
    got = laser_strays.replay(laser_strays.stray_capture(
        tmp_path / "c", 0.0, 6, True, blocks=[(t0, end, -1500)], outage=(t0, t0 + 2.0)))
    assert dict(got["passes"])[1] == clean[1]
    for no, kg in got["passes"][1:]:
        assert kg is None or abs(kg - clean[no]) < 0.01 * clean[no], (no, kg, clean[no])
    assert all(got["reasons"][no].startswith("the crowd laser may not be on the handle")
               for no, kg in got["passes"][1:] if kg is None)


def test_no_pass_is_weighed_wrong_silently_when_something_came_while_the_laser_was_down(
        tmp_path: Path, base: dict[str, Any], clean: dict[int, float]) -> None:
    """The same fault as above, and what makes it seen, the misfit: each of passes 2 and 3
    is not weighed, or within 1 %, or carries a misfit above the warning level (before
    the crowd's doubt: weighed tonnes off on a crowd 1.5 m short, with the model unable
    to balance their currents); pass 1, before the fault, is exact and not flagged."""
    from shoveld.payload.misfit import MISFIT_WARN

    _, a, b = base["spans"][1]
    end = base["spans"][-1][2] + 100.0
    t0 = a + 0.5
    got = laser_strays.replay(laser_strays.stray_capture(
        tmp_path / "c", 0.0, 6, True, blocks=[(t0, end, -1500)], outage=(t0, t0 + 2.0)))
    fits = got["misfits"]
    assert 0.0 < fits[1] <= MISFIT_WARN and dict(got["passes"])[1] == clean[1]
    for no, kg in got["passes"][1:]:
        right = kg is None or abs(kg - clean[no]) < 0.01 * clean[no]
        assert right or fits[no] > MISFIT_WARN, (no, kg, clean[no], fits[no])
