"""``shoveld.words.n_of``: counts said the way a person writes them, from any layer."""

from __future__ import annotations

import subprocess
import sys

from shoveld.words import n_of


def test_one_is_singular_every_other_count_plural() -> None:
    assert n_of(1, "pass", "passes") == "1 pass"
    assert n_of(2, "pass", "passes") == "2 passes"
    assert n_of(0, "truck", "trucks") == "0 trucks"  # "0 truck" is not English either
    assert n_of(1, "verified pass", "verified passes") == "1 verified pass"
    # a count missing from a message reads as before, not as an error on a screen
    assert n_of(None, "pass", "passes") == "None passes"


def test_the_helper_does_not_pull_in_the_command_line() -> None:
    """Plots, the report writer, the engine and the daemon use it: importing it must not
    import ``shoveld.cli`` (argparse, the commands) into them."""
    code = ("import sys, shoveld.words; "
            "print(sorted(m for m in sys.modules if m.startswith('shoveld.')))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       check=True)
    assert r.stdout.strip() == "['shoveld.words']", r.stdout
