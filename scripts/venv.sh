#!/usr/bin/env bash
# Create .venv with shoveld and its dev tools if it is missing or stale; print its path.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
venv="$here/.venv"
stamp="$venv/.installed-$(sha1sum "$here/pyproject.toml" | cut -c1-12)"
if [ ! -f "$stamp" ]; then
  python3 -m venv "$venv" >&2
  "$venv/bin/pip" install -q --upgrade pip >&2 || true
  "$venv/bin/pip" install -q -e "$here[dev]" >&2
  touch "$stamp"
fi
echo "$venv"
