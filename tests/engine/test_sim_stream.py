"""A long simulated run is made truck by truck in segments (``iter_cycles``), so that
its memory does not grow with its length; the segments must join into one run."""

from __future__ import annotations

import numpy as np

from shoveld.sim.machine import Machine
from shoveld.sim.scenario import iter_cycles, simulate_cycles


def test_a_short_run_is_one_segment() -> None:
    parts = list(iter_cycles(5, seed=4, chunk_passes=8))
    assert len(parts) == 1 and parts[0].motion is not None


def test_segments_join_into_one_continuous_run() -> None:
    m = Machine.draw(2)
    parts = list(iter_cycles(20, seed=8, chunk_passes=6, machine=m, truck_target_kg=62000.0,
                             verified_fraction=0.5))
    assert len(parts) >= 3
    # Each segment but the last ends at a truck exchange and holds whole trucks.
    for a, b in zip(parts, parts[1:], strict=False):
        assert a.passes[-1].truck + 1 == b.passes[0].truck
    whole = simulate_cycles(20, seed=8, chunk_passes=6, machine=m, truck_target_kg=62000.0,
                            verified_fraction=0.5)
    t = whole.table.time
    assert np.allclose(np.diff(t), 0.02, atol=1e-9)  # one clock, no gap, no overlap
    assert [p.index for p in whole.passes] == list(range(1, 21))
    starts = [p.phases["dig"][0] for p in whole.passes]
    assert all(b > a for a, b in zip(starts, starts[1:], strict=False)) and starts[-1] < t[-1]
    # A verified payload is written where its pass is, in every segment.
    col = whole.table.columns["payload_kg"]
    for p in whole.passes:
        at = (t >= p.phases["lift"][0]) & (t < p.phases["dump"][0])
        assert np.all(col[at] == p.payload_kg) if p.verified else np.all(np.isnan(col[at]))
    # The dipper rests across a join: no step in the arm or in the slowly drifting
    # handle sensor beyond the noise of one sample.
    handle = whole.table.columns["handle_deg"]
    for part in parts[1:]:
        k = int(np.searchsorted(t, part.table.time[0]))
        step = abs(handle[k] - handle[k - 1])
        assert step < 6 * m.sensors.handle_deg
