"""A pass whose crowd is not the handle's is not weighed.

The driver takes something that stayed in its beam as its target after
``other_target_s``; the assembler marks that tick with ``CROWD_TARGET_CHANGED``. The
crowd before and after it are not of the same thing, so a payload made of both would be
tonnes off while it looked valid (bench/laser_strays.py --blocks 10). Something taken
between passes that stays, or a stuck laser, gives a crowd that does not move through a
dig, which no real dig does (``min_crowd_travel_m``).
"""

from __future__ import annotations

import dataclasses
import math

from shoveld.engine.loop import Engine, EngineConfig, LiveEstimate, PassResult
from shoveld.model.params import ModelParams
from shoveld.sample import CROWD_TARGET_CHANGED, Sample, samples_from_table
from shoveld.sim.scenario import SimResult


def _run(params: ModelParams, samples: list[Sample], *,
         min_crowd_travel_m: float = EngineConfig.min_crowd_travel_m
         ) -> tuple[list[PassResult], list[LiveEstimate]]:
    eng = Engine(params, EngineConfig(rate_hz=1.0 / (samples[1].time_s - samples[0].time_s),
                                      min_crowd_travel_m=min_crowd_travel_m))
    passes: list[PassResult] = []
    live: list[LiveEstimate] = []
    for s in samples:
        for ev in eng.step(s):
            if isinstance(ev, PassResult):
                passes.append(ev)
            elif isinstance(ev, LiveEstimate):
                live.append(ev)
    return passes, live


def _mark(samples: list[Sample], t: float) -> int:
    """Mark the first sample at or after ``t`` (its crowd stays as it was)."""
    i = next(i for i, s in enumerate(samples) if s.time_s >= t)
    s = samples[i]
    samples[i] = dataclasses.replace(s, invalid=s.invalid | {CROWD_TARGET_CHANGED})
    return i


def test_a_pass_across_a_change_of_target_is_not_weighed(params: ModelParams,
                                                          cycles: SimResult) -> None:
    """Marked in pass 2's swing, in pass 4's dig, and in the return after pass 5's
    dump: passes 2 and 4 are not weighed and say why; the live estimate of pass 2 is not
    valid from the mark to the dump; every other pass is as without the marks, to the
    bit (a change between passes costs nothing)."""
    clean = list(samples_from_table(cycles.table))
    ref, _ = _run(params, clean)
    assert len(ref) == len(cycles.passes) >= 7 and all(p.valid for p in ref)
    marked = list(clean)
    swing = cycles.passes[1].phases["swing"]
    i = _mark(marked, (swing[0] + swing[1]) / 2)
    dig = cycles.passes[3].phases["dig"]
    _mark(marked, (dig[0] + dig[1]) / 2)
    back = cycles.passes[4].phases["return"]
    _mark(marked, (back[0] + back[1]) / 2)
    got, live = _run(params, marked)
    assert [p.index for p in got] == [p.index for p in ref]
    for p, r in zip(got, ref, strict=True):
        if p.index in (2, 4):
            assert not p.valid and p.as_dict()["payload_kg"] is None
            assert "laser changed target" in p.reason, p.reason
        else:
            assert p.valid and p.payload_kg == r.payload_kg and p.std_kg == r.std_kg
    dump = next(p.end_s for p in got if p.index == 2)
    after = [e for e in live[i:] if e.time_s < dump and e.phase in ("lift", "swing")]
    assert after and not any(e.valid for e in after)
    before = [e for e in live[:i] if e.phase in ("lift", "swing")
              and e.time_s > ref[1].start_s and not math.isnan(e.payload_kg)]
    assert any(e.valid for e in before)


def test_a_crowd_that_stands_still_through_a_pass_is_not_weighed(
        params: ModelParams, cycles: SimResult) -> None:
    """The laser reads one distance from the return after pass 3 on (something lodged in
    its beam, taken between passes, or the laser stuck): passes 4 on are not weighed and
    say why. Without the test they are weighed, tonnes off the truth, and look valid."""
    clean = list(samples_from_table(cycles.table))
    back = cycles.passes[2].phases["return"]
    i = next(i for i, s in enumerate(clean) if s.time_s >= (back[0] + back[1]) / 2)
    frozen = clean[:i] + [dataclasses.replace(s, crowd_m=clean[i].crowd_m) for s in clean[i:]]
    got, _ = _run(params, frozen)
    ref, _ = _run(params, clean)
    assert [p.index for p in got] == [p.index for p in ref]
    assert all(p.valid and p.payload_kg == r.payload_kg for p, r in zip(got[:3], ref[:3],
                                                                      strict=True))
    assert not any(p.valid for p in got[3:])
    assert all(p.reason.startswith("the crowd moved 0.00 m in the pass") for p in got[3:])
    blind, _ = _run(params, frozen, min_crowd_travel_m=0.0)
    assert all(p.valid for p in blind)
    truth = [p.payload_kg for p in cycles.passes]
    assert max(abs(p.payload_kg - kg) for p, kg in zip(blind[3:], truth[3:], strict=True)) > 2000
