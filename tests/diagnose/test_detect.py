"""Hide an effect in simulated data; the diagnosis must name it and the gain must show.

Each effect's magnitude and seed are drawn (per effect name) from the effect's
typical range; ``bench/diagnose_matrix.py`` runs many seeds for the detection matrix.
"""

from __future__ import annotations

import os
import zlib

import numpy as np
import pytest

from shoveld.diagnose import MODELLED_BY_BASE, diagnose
from shoveld.diagnose.data import RATED_PAYLOAD_KG
from shoveld.sim.effects import SIM_EFFECTS
from tests.diagnose.conftest import draw, session

# Known misses on the realistic machine, measured (docs/diagnosis.md, "What is weak"):
# not strict, because each sits near a threshold and another machine's arithmetic may
# tip it either way.
KNOWN_MISSES: dict[str, str] = {
    "boom_suspension_spring":
        "1.6 deg at 1 MN on this machine (seed 75611) moves the payload by about 20 kg "
        "(base RMS 69 kg against 66 kg on a clean machine; the issue's size is 175 kg): "
        "since the term's column follows the bail rope's moment its held-out t is 2.95, "
        "under 3.39 (3.47 before), though it takes more of the residual (3.0 % against "
        "2.8 %) and cuts the payload RMS further (69 -> 40 kg against 42 kg)"}
"""The time skew's miss is gone since 2026-11-27 (the delay model takes 26 % of the
held-out residual and cuts the payload RMS from 162 to 98 kg over 14 passes, where the
paired payload tests sat at their p < 0.025 threshold): it is named by
``decisive_gain``. The boom spring's here came with its pose (twentieth session,
docs/diagnosis.md): on the bench's machines its t fell a little too (5.19, 3.46, 5.03
-> 4.47, 3.22, 4.86) while it was named on 2 of 3 (1 before)."""

RUN_KNOWN_MISSES = bool(os.environ.get("SHOVELD_RUN_KNOWN_MISSES"))
"""A known miss is not run unless this is set: not strict, its outcome fails nothing
either way, and the boom spring's took two of the CI's 30 minutes on a slow machine
(2026-11-30). ``bench/diagnose_matrix.py`` measures the misses over many seeds."""


@pytest.mark.parametrize("effect", [
    pytest.param(e, marks=pytest.mark.xfail(reason=KNOWN_MISSES[e], strict=False,
                                            run=RUN_KNOWN_MISSES))
    if e in KNOWN_MISSES else e for e in sorted(SIM_EFFECTS)])
def test_hidden_effect_is_named_first_and_cuts_the_payload_error(effect: str) -> None:
    mag, seed = draw(effect)
    calib, measured, ops = session({effect: mag}, seed)
    d = diagnose(calib, measured, engine=False)
    if effect in MODELLED_BY_BASE:
        # the base model carries it: nothing to name, and the payload is already good
        assert d.found == [], f"{effect}: found {d.found}"
        assert d.payload("base")["rms_kg"] < 0.005 * RATED_PAYLOAD_KG
        return
    assert d.found, f"{effect}={mag:.3g} (seed {seed}) not found"
    assert d.found[0] == effect, f"{effect}={mag:.3g} (seed {seed}): found {d.found}"
    base, ext = d.payload("base"), d.payload("extended")
    assert ext["passes"] == base["passes"] > 5
    # the gain: the extended model halves the held-out payload RMS, or brings it
    # within 1.5 x the Cramer-Rao bound of the verified passes
    crb = float(np.mean([p.crb_kg for p in ops.passes if p.verified]))
    assert ext["rms_kg"] <= max(0.5 * base["rms_kg"], 1.5 * crb), (base, ext, crb)


def test_data_without_any_effect_gives_nothing() -> None:
    calib, measured, _ = session({}, 424242)
    d = diagnose(calib, measured, engine=False)
    assert d.found == []
    js = d.as_json()
    assert js["found"] == [] and len(js["ranked"]) == len(SIM_EFFECTS) - len(MODELLED_BY_BASE)
    assert js["base"]["payload"] == js["extended"]["payload"]


def test_two_effects_are_both_found_larger_first() -> None:
    """The swing and the rope's weight. After the swing term the rope's makes the held-out
    residual 1.2 % worse and cuts the payload RMS from 167 to 108 kg: it is named on the
    payload, at 123 +- 8 kg/m (140 simulated). A known miss until 2026-11-27, when the
    residual was its only judge (docs/diagnosis.md)."""
    # The centrifugal error of the swing is several times the rope weight's.
    calib, measured, _ = session({"swing_centrifugal": 4.0, "hoist_rope_mass": 140.0}, 5150)
    d = diagnose(calib, measured, engine=False)
    assert d.found[:2] == ["swing_centrifugal", "hoist_rope_mass"], d.found


def test_saturation_and_the_swing_at_once_are_both_named() -> None:
    """Saturation and the swing's centrifugal load at once, magnitudes and seed drawn as
    for the single effects: both are named and the payload improves. Here the swing pays
    alone and the saturation follows (on some bench machines neither pays alone and the
    two are added together, ``select._pair``; test_select.py tests that rule)."""
    spec = {n: draw(n)[0] for n in ("current_saturation", "swing_centrifugal")}
    seed = zlib.crc32("+".join(spec).encode()) % 100_000
    calib, measured, _ = session(spec, seed)
    d = diagnose(calib, measured, engine=False)
    assert set(d.found[:2]) == set(spec), d.found
    assert d.payload("extended")["rms_kg"] < d.payload("base")["rms_kg"]


def test_a_pair_reads_as_added_only_when_both_of_its_terms_are() -> None:
    from shoveld.diagnose.report import added

    assert added("swing_centrifugal+current_saturation",
                 ["swing_centrifugal", "current_saturation"])
    assert not added("swing_centrifugal+current_saturation", ["swing_centrifugal"])
    assert added("ground_slope", ["ground_slope"]) and not added("ground_slope", [])
