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
