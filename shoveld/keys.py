"""The words of the site's Zenoh keys, each rule in one place.

The config (``shovel.id``, ``zenoh.prefix``, device names), the PKI (a peer's name is
its certificate's common name and, for a shovel, its id) and the command line
(``replay --id``, the screens' ``--shovel`` and ``--prefix``) hold the same words to the
same rules. Light on purpose: every command's ``--help`` loads it.
"""

from __future__ import annotations

import re

CHUNK = re.compile(r"[A-Za-z0-9_.-]+")
"""One plain key chunk (no '/', no wildcard): a device's name."""
NAME = re.compile(r"[A-Za-z0-9_.-]{1,64}")
"""A shovel's id or a peer's name: one key chunk of at most 64 characters, as X.509
holds in a certificate's common name."""
PREFIX = re.compile(r"[A-Za-z0-9_.-]+(/[A-Za-z0-9_.-]+)*")
"""The site's key prefix: plain chunks joined by '/' (e.g. ``shovel``, ``site1/shovel``)."""
