"""Run the engine over a signals table: the offline face of the live pipeline."""

from __future__ import annotations

from dataclasses import dataclass, field

from shoveld.engine.loop import (
    EmptyCheck,
    Engine,
    EngineConfig,
    LiveEstimate,
    PassResult,
    TruckResult,
    run_engine,
)
from shoveld.model.params import ModelParams
from shoveld.payload.trucks import Truck
from shoveld.sample import samples_from_table
from shoveld.signals.table import SignalsTable


@dataclass
class Estimate:
    passes: list[PassResult] = field(default_factory=list)
    trucks: list[Truck] = field(default_factory=list)
    live: list[LiveEstimate] = field(default_factory=list)
    """Every tick's live estimate, when asked for (plots)."""
    empties: list[EmptyCheck] = field(default_factory=list)
    """The empty dipper weighed on each return."""


def estimate_table(table: SignalsTable, params: ModelParams, cfg: EngineConfig | None = None,
                   first_pass: int = 1, first_truck: int = 1, keep_live: bool = False
                   ) -> Estimate:
    """Passes and closed trucks of one table (rate taken from the table)."""
    base = cfg or EngineConfig()
    rate = table.sample_rate_hz
    cfg = EngineConfig(**{**base.__dict__, "rate_hz": rate})
    eng = Engine(params, cfg, first_pass=first_pass, first_truck=first_truck)
    out = Estimate()
    for ev in run_engine(samples_from_table(table), eng):
        if isinstance(ev, PassResult):
            out.passes.append(ev)
        elif isinstance(ev, TruckResult) and ev.closed:
            out.trucks.append(ev.truck)
        elif isinstance(ev, EmptyCheck):
            out.empties.append(ev)
        elif keep_live and isinstance(ev, LiveEstimate):
            out.live.append(ev)
    return out
