"""The settle time's samples: kept in a pass when they agree with the rest of it, refused
when the bank still pulls on the dipper (``EngineConfig.settle_test_z``)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from shoveld.engine import loop
from shoveld.engine.loop import EngineConfig, LiveEstimate
from shoveld.engine.offline import Estimate, estimate_table
from shoveld.model.params import ModelParams
from shoveld.signals.table import SignalsTable
from shoveld.sim.scenario import SimResult

NEVER = EngineConfig(settle_test_z=0.0)
"""The settle time's samples never used (the engine before 2026-11-27)."""
ALWAYS = EngineConfig(settle_s=0.0)
"""... always used, whatever they say (no settle time)."""


def lift_starts(est: Estimate) -> list[float]:
    """The ticks at which the engine saw the dipper leave the bank (dig -> lift)."""
    live = est.live
    return [b.time_s for a, b in zip(live, live[1:], strict=False)
            if a.phase == "dig" and b.phase == "lift"]


def with_bank_pull(table: SignalsTable, starts: list[float], settle_s: float,
                   extra_a: float) -> SignalsTable:
    """The table with the hoist pulling ``extra_a`` harder through each settle time, as a
    bank that still holds the dipper would make it (the joints move as before)."""
    cols = {k: v.copy() for k, v in table.columns.items()}
    t = cols["time_s"]
    for t0 in starts:
        sel = (t >= t0) & (t < t0 + settle_s)
        cols["hoist1_a"][sel] += extra_a / 2
        cols["hoist2_a"][sel] += extra_a / 2
    return SignalsTable.from_arrays(meta=dict(table.meta), **cols)


def payloads(est: Estimate) -> np.ndarray:
    return np.array([p.payload_kg for p in est.passes])


def refusals(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records
            if r.name == "shoveld.engine.loop" and "out of the bank left out" in r.getMessage()]


def test_clean_settle_time_is_kept(params: ModelParams, cycles: SimResult,
                                   monkeypatch: pytest.MonkeyPatch,
                                   caplog: pytest.LogCaptureFixture) -> None:
    """Without bank contact the test keeps the settle time's samples in nearly every pass
    (a 2-sigma test refuses about one pass in twenty), and they move it little."""
    # the second filter takes its rows in updates of 4 blocks (64 by default, more than
    # these 50 Hz passes have), so the folding is tested too
    monkeypatch.setattr(loop, "FOLD_BLOCKS", 4)
    # the refusals of this estimate only (the root logger's level is whatever the tests
    # before left: the other estimates may log too)
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="shoveld.engine.loop"):
        new = estimate_table(cycles.table, params)
    said = refusals(caplog)
    old = estimate_table(cycles.table, params, NEVER)
    n_new = np.array([p.samples for p in new.passes])
    n_old = np.array([p.samples for p in old.passes])
    assert len(n_new) == len(n_old) == len(cycles.passes)
    assert np.all(n_new >= n_old)
    assert np.count_nonzero(n_new > n_old) >= 0.8 * len(n_new)
    # each refusal is logged for the field engineer, and only those
    assert len(said) == np.count_nonzero(n_new == n_old)
    stds = np.array([p.std_kg for p in old.passes])
    assert np.all(np.abs(payloads(new) - payloads(old)) < 2 * stds)
    # where kept, the pass is the one with no settle time at all: the same rows, kept
    # aside and folded into the second filter a few blocks at a time
    always = estimate_table(cycles.table, params, ALWAYS)
    kept = n_new > n_old
    assert [p.samples for p in always.passes] == [
        p.samples if k else a.samples
        for p, a, k in zip(new.passes, always.passes, kept, strict=True)]
    np.testing.assert_allclose(payloads(new)[kept], payloads(always)[kept], rtol=1e-9)
    assert min(n_new) > 20 * loop.FOLD_BLOCKS


def test_bank_pull_in_the_settle_time_is_refused(params: ModelParams, cycles: SimResult,
                                                 caplog: pytest.LogCaptureFixture) -> None:
    """A settle time the bank still pulls on is left out: the pass is what it was without
    the settle time; taking it anyway would put the pull into the payload."""
    starts = lift_starts(estimate_table(cycles.table, params, keep_live=True))
    assert len(starts) == len(cycles.passes)
    settle = EngineConfig().settle_s
    pulled = with_bank_pull(cycles.table, starts, settle, extra_a=300.0)
    caplog.clear()  # the estimate above may have logged (the root logger's level)
    with caplog.at_level(logging.INFO, logger="shoveld.engine.loop"):
        tested = estimate_table(pulled, params)
    said = refusals(caplog)
    assert len(said) == len(cycles.passes)
    assert said[-1].endswith(f"{len(said)} of {len(said)} passes left out so far")
    never = estimate_table(pulled, params, NEVER)
    always = estimate_table(pulled, params, ALWAYS)
    assert [p.samples for p in tested.passes] == [p.samples for p in never.passes]
    np.testing.assert_allclose(payloads(tested), payloads(never), rtol=1e-9, atol=1e-6)
    # the pull is there to be refused: with the samples it moves every pass up, by far
    # more than the pass's own std
    shift = payloads(always) - payloads(never)
    stds = np.array([p.std_kg for p in never.passes])
    assert np.all(shift > 3 * stds), (shift, stds)


@pytest.mark.parametrize("z", [2.0, 0.0], ids=["tested", "never"])
def test_live_estimate_is_the_settled_one(params: ModelParams, cycles: SimResult,
                                          z: float) -> None:
    """The live payload the cab shows during a pass comes from the settled samples only,
    whatever the final one keeps: the test changes nothing before the dump. (One sample
    a block, so that both filters take their rows at the same ticks.)"""
    a = estimate_table(cycles.table, params, EngineConfig(settle_test_z=z, batch=1),
                       keep_live=True).live
    b = estimate_table(cycles.table, params, EngineConfig(settle_test_z=0.0, batch=1),
                       keep_live=True).live
    assert len(a) == len(b)
    va = np.array([e.payload_kg for e in a if e.phase in ("lift", "swing")])
    vb = np.array([e.payload_kg for e in b if e.phase in ("lift", "swing")])
    np.testing.assert_allclose(va, vb, rtol=1e-9, atol=1e-6, equal_nan=True)
    assert isinstance(a[0], LiveEstimate)

