"""The unit file: ``systemd-analyze verify`` passes and the exposure stays well under 3.0."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from .conftest import ROOT

UNIT = ROOT / "systemd" / "shoveld.service"
ANALYZE = shutil.which("systemd-analyze") or "/usr/bin/systemd-analyze"

pytestmark = pytest.mark.skipif(not Path(ANALYZE).exists(), reason="no systemd-analyze")


def test_verify_in_a_root_where_the_binary_exists(tmp_path: Path) -> None:
    """verify checks that ExecStart's binary exists; /usr/bin/shoveld is what a package
    installs, so the check runs in a scratch root holding it and the system's units."""
    root = tmp_path / "root"
    (root / "usr/bin").mkdir(parents=True)
    (root / "etc/systemd/system").mkdir(parents=True)
    exe = root / "usr/bin/shoveld"
    exe.write_text("#!/bin/sh\n")
    exe.chmod(0o755)
    shutil.copy(UNIT, root / "etc/systemd/system/shoveld.service")
    units = Path("/lib/systemd/system")
    if not units.is_dir():
        pytest.skip("no system units to verify against")
    shutil.copytree(units, root / "usr/lib/systemd/system", symlinks=True)
    r = subprocess.run([ANALYZE, "verify", f"--root={root}", "shoveld.service"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.strip() == "" and r.stderr.strip() == ""


def test_verify_here_only_misses_the_installed_binary() -> None:
    r = subprocess.run([ANALYZE, "verify", str(UNIT)], capture_output=True, text=True)
    complaints = {line for line in (r.stdout + r.stderr).splitlines() if line.strip()}
    assert complaints <= {"shoveld.service: Command /usr/bin/shoveld is not executable: "
                          "No such file or directory"}


def test_security_exposure_well_under_3() -> None:
    r = subprocess.run([ANALYZE, "security", "--offline=true", str(UNIT)],
                       capture_output=True, text=True)
    m = re.search(r"Overall exposure level for shoveld.service: (\d+\.\d+)", r.stdout)
    assert m, r.stdout + r.stderr
    assert float(m.group(1)) < 2.0


def test_unit_essentials() -> None:
    text = UNIT.read_text()
    for line in ("Type=notify", "Restart=on-failure", "WatchdogSec=", "StateDirectory=shoveld",
                 "User=shoveld", "SupplementaryGroups=dialout", "DeviceAllow=char-ttyUSB rw",
                 "ExecStart=/usr/bin/shoveld run --config /etc/shoveld/shoveld.toml"):
        assert line in text
    sysusers = (ROOT / "systemd" / "shoveld.sysusers").read_text()
    assert "u shoveld" in sysusers and "m shoveld dialout" in sysusers


def test_install_script_stages_the_tree_and_removes_it(tmp_path: Path) -> None:
    """``scripts/install.sh --prefix`` (a staging root: no user, no systemctl)."""
    import os
    import stat
    import subprocess

    script = ROOT / "scripts" / "install.sh"
    root = tmp_path / "root"
    r = subprocess.run([str(script), "--prefix", str(root), "--no-deps"], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert os.readlink(root / "usr/bin/shoveld") == "/opt/shoveld/venv/bin/shoveld"
    assert (root / "opt/shoveld/venv/bin/shoveld").exists()
    unit = (root / "etc/systemd/system/shoveld.service").read_text()
    docs = [d.removeprefix("file:") for line in unit.splitlines()
            if line.startswith("Documentation=") for d in line.split("=", 1)[1].split()]
    assert docs and all((root / d.lstrip("/")).is_file() for d in docs), docs
    assert (root / "usr/lib/sysusers.d/shoveld.conf").is_file()
    assert stat.S_IMODE((root / "var/lib/shoveld").stat().st_mode) == 0o750
    cfg = root / "etc/shoveld/shoveld.toml"
    cfg.write_text(cfg.read_text() + "\n# site edits\n")
    r = subprocess.run([str(script), "--prefix", str(root), "--no-deps"], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0 and "kept the existing" in r.stdout
    assert cfg.read_text().endswith("# site edits\n")  # a re-install keeps the site's config
    r = subprocess.run([str(script), "--prefix", str(root), "--uninstall"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and not (root / "opt/shoveld").exists()
    assert not (root / "usr/bin/shoveld").is_symlink() and cfg.exists()
    assert (root / "var/lib/shoveld").is_dir()  # the pass log stays unless --purge
    r = subprocess.run([str(script), "--prefix", str(root), "--uninstall", "--purge"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and not cfg.exists() and not (root / "var/lib/shoveld").exists()
