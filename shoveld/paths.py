"""Where an installed shovel keeps its files; a module of constants, so that a command's
``--help`` can name them without importing the daemon."""

from __future__ import annotations

import os
from pathlib import Path

DEFAULT_CONFIG = "/etc/shoveld/shoveld.toml"
"""The daemon's configuration, as the systemd unit gives it."""
LOCAL_CONFIG = "shoveld.toml"
CONFIG_ENV = "SHOVELD_CONFIG"
CONFIG_SEARCH = f"${CONFIG_ENV}, else ./{LOCAL_CONFIG}, else {DEFAULT_CONFIG}"
"""How a command finds the configuration when none is given (for ``--help``)."""


def find_config() -> str:
    """The configuration to use when none is given: ``$SHOVELD_CONFIG``, a
    ``shoveld.toml`` in the current folder (a laptop, a test bench), else the installed
    one under /etc (the shovel's computer)."""
    env = os.environ.get(CONFIG_ENV)
    if env:
        return env
    if Path(LOCAL_CONFIG).is_file():
        return LOCAL_CONFIG
    return DEFAULT_CONFIG
