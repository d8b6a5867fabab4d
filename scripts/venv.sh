#!/usr/bin/env bash
# Create .venv with shoveld and its dev tools if it is missing or stale; print its path.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
venv="$here/.venv"
stamp="$venv/.installed-$(sha1sum "$here/pyproject.toml" | cut -c1-12)"
if [ ! -f "$stamp" ]; then
  echo "setting up $venv (first run, about a minute)..." >&2
  log=$(mktemp)
  if ! { python3 -m venv "$venv" && "$venv/bin/pip" install -q -e "$here[dev]"; } >"$log" 2>&1
  then
    cat "$log" >&2
    echo "error: could not install shoveld into $venv (log above)" >&2
    exit 1
  fi
  rm -f "$log" "$venv"/.installed-*
  touch "$stamp"
fi
echo "$venv"
