#!/usr/bin/env bash
# Install shoveld on the shovel's computer, or remove it.
#
#   sudo scripts/install.sh                 # the package in /opt/shoveld/venv, /usr/bin/shoveld,
#                                           # the unit, the user, /etc/shoveld/shoveld.toml (kept
#                                           # if present), /var/lib/shoveld, the docs
#   sudo scripts/install.sh --uninstall     # removes all that but the config and the pass log
#   sudo scripts/install.sh --uninstall --purge   # ... and those too
#   scripts/install.sh --prefix DIR         # the same tree under DIR (a staging root; no
#                                           # systemctl, no user), e.g. to build an image
#
# --no-deps installs the package without its dependencies (an image that has them).
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
prefix=""
mode=install
purge=0
pip_args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --prefix) prefix=${2:?--prefix needs a folder}; shift 2 ;;
    --uninstall) mode=uninstall; shift ;;
    --purge) purge=1; shift ;;
    --no-deps) pip_args+=(--no-deps); shift ;;
    -h|--help) sed -n '2,13p' "$0"; exit 0 ;;
    *) echo "install.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
root=${prefix%/}
live=0  # on the real root as root: users, ownership, systemctl
if [ -z "$root" ] && [ "$(id -u)" = 0 ]; then live=1; fi
if [ -z "$root" ] && [ "$live" = 0 ]; then
  echo "install.sh: run as root to install into /, or give --prefix DIR" >&2; exit 2
fi

venv=$root/opt/shoveld/venv
bin=$root/usr/bin/shoveld
unit=$root/etc/systemd/system/shoveld.service
sysusers=$root/usr/lib/sysusers.d/shoveld.conf
docs=$root/usr/share/doc/shoveld
etc=$root/etc/shoveld
state=$root/var/lib/shoveld

if [ "$mode" = uninstall ]; then
  if [ "$live" = 1 ] && command -v systemctl >/dev/null; then
    systemctl disable --now shoveld.service 2>/dev/null || true
  fi
  rm -rf "$root/opt/shoveld" "$docs"
  rm -f "$bin" "$unit" "$sysusers"
  if [ "$purge" = 1 ]; then
    rm -rf "$etc" "$state"
    echo "removed shoveld, its configuration and its pass log"
  else
    echo "removed shoveld; kept $etc and $state (the pass log): --purge removes them"
  fi
  if [ "$live" = 1 ] && command -v systemctl >/dev/null; then systemctl daemon-reload; fi
  exit 0
fi

mkdir -p "$(dirname "$venv")" "$(dirname "$bin")" "$(dirname "$unit")" \
         "$(dirname "$sysusers")" "$docs" "$etc"
python3 -m venv "$venv"
"$venv/bin/pip" install -q ${pip_args[@]+"${pip_args[@]}"} "$here"
ln -sfn /opt/shoveld/venv/bin/shoveld "$bin"
install -m 0644 "$here/systemd/shoveld.service" "$unit"
install -m 0644 "$here/systemd/shoveld.sysusers" "$sysusers"
install -m 0644 "$here/README.md" "$docs/README.md"
cp -r "$here/docs/." "$docs/"
if [ -e "$etc/shoveld.toml" ]; then
  echo "kept the existing $etc/shoveld.toml"
else
  install -m 0640 "$here/examples/shoveld.toml" "$etc/shoveld.toml"
  echo "wrote $etc/shoveld.toml from the example: set the shovel's id, params and devices"
fi
install -d -m 0750 "$state"
if [ "$live" = 1 ]; then
  systemd-sysusers "$sysusers"
  chown shoveld:shoveld "$state"
  chgrp shoveld "$etc/shoveld.toml"
  systemctl daemon-reload
  echo "installed; check the config with 'shoveld check-config', then: systemctl enable --now shoveld"
else
  echo "installed under $root (a staging root: no user made, no systemctl)"
fi
