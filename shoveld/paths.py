"""Where an installed shovel keeps its files; a module of constants, so that a command's
``--help`` can name them without importing the daemon."""

from __future__ import annotations

DEFAULT_CONFIG = "/etc/shoveld/shoveld.toml"
"""The daemon's configuration, as the systemd unit gives it."""
