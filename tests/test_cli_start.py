"""The command line's start: a named subcommand loads only its own module, parses as the
full parser does, and the daemon's commands keep numpy's OpenBLAS to one thread."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from shoveld.cli import SUBCOMMANDS, _named_command, build_parser

ROOT = Path(__file__).resolve().parents[1]
CAPTURE = ROOT / "hil_fixtures" / "captures" / "daemon-e2e"


def _in_fresh_python(code: str, env: dict[str, str] | None = None) -> dict[str, object]:
    """Run ``code`` in a new interpreter (a clean ``sys.modules``); it prints one JSON
    object as its last line."""
    e = {**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=e, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_the_command_word_is_found_after_the_global_options() -> None:
    assert _named_command(["replay", "x", "--fast"]) == "replay"
    assert _named_command(["-v", "-v", "replay", "x"]) == "replay"
    assert _named_command(["-vv", "check-config", "--config", "a"]) == "check_config"
    assert _named_command(["--help"]) is None
    assert _named_command([]) is None
    assert _named_command(["repla", "x"]) is None  # not a command: the full parser says so
    assert _named_command(["--", "replay"]) is None


@pytest.mark.parametrize("argv", [
    ["replay", str(CAPTURE), "--fast", "--listen", "tcp/127.0.0.1:7447", "--until", "3"],
    ["-v", "replay", str(CAPTURE), "--speed", "2", "--json"],
    ["check-config", "x.toml", "--no-params"],
    ["passes", "--state-dir", "/tmp/x", "--since", "2026-11-26"],
])
def test_one_subcommands_parser_parses_as_the_full_one(argv: list[str]) -> None:
    only = _named_command(argv)
    assert only is not None
    a = vars(build_parser(only).parse_args(argv))
    b = vars(build_parser().parse_args(argv))
    assert a == b


def test_a_named_command_loads_only_its_own_module_and_no_numpy() -> None:
    got = _in_fresh_python(
        "import json, sys\n"
        "from shoveld.cli import main\n"
        "try:\n"
        "    main(['replay', '--help'])\n"
        "except SystemExit as e:\n"
        "    code = e.code\n"
        "print(json.dumps({'code': code, 'numpy': 'numpy' in sys.modules,\n"
        "    'cli': sorted(m for m in sys.modules if m.startswith('shoveld.cli.'))}))")
    # no other subcommand's module; the shared option types (``shoveld.cli.options``, a
    # few argparse types) are all it loads beside its own
    assert got == {"code": 0, "numpy": False,
                   "cli": ["shoveld.cli.options", "shoveld.cli.replay"]}


def test_the_top_level_help_still_lists_every_command() -> None:
    r = subprocess.run([sys.executable, "-m", "shoveld", "--help"], capture_output=True,
                       text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                       timeout=60)
    assert r.returncode == 0
    for name in SUBCOMMANDS:
        assert name.replace("_", "-") in r.stdout
    r = subprocess.run([sys.executable, "-m", "shoveld", "nosuch"], capture_output=True,
                       text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                       timeout=60)
    assert r.returncode == 2 and "invalid choice" in r.stderr and "replay" in r.stderr


@pytest.mark.parametrize(("given", "expected"), [(None, "1"), ("3", "3")])
def test_replay_keeps_openblas_to_one_thread_unless_told(given: str | None,
                                                         expected: str) -> None:
    """Set before numpy loads (so it takes effect), and a value the user set is kept."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    code = ("import json, os, sys\n"
            "from shoveld.cli import main\n"
            "before = 'numpy' in sys.modules\n"
            "rc = main(['replay', 'no-such-capture', '--fast', '--params', 'no.toml'])\n"
            "print(json.dumps({'rc': rc, 'numpy_before': before,\n"
            "    'numpy_after': 'numpy' in sys.modules,\n"
            "    'threads': os.environ.get('OPENBLAS_NUM_THREADS')}))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**env, "PYTHONPATH": str(ROOT)}, cwd=ROOT, timeout=120)
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got == {"rc": 2, "numpy_before": False, "numpy_after": True, "threads": expected}


def test_a_fast_replay_loads_no_module_it_does_not_use() -> None:
    """The whole ``shoveld replay --fast`` (to 2 s of the capture): no other subcommand,
    no socket module (systemd's notify socket is opened only under systemd), no pymodbus
    (the in-memory Modbus client needs it only for a recorded timeout), no scipy, no
    uuid (the threaded replay's CAN bus names)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    got = _in_fresh_python(
        "import json, sys\n"
        "from shoveld.cli import main\n"
        f"rc = main(['replay', {str(CAPTURE)!r}, '--fast', '--until', '2',\n"
        f"           '--listen', 'tcp/127.0.0.1:{port}'])\n"
        "mods = set(sys.modules)\n"
        "import gc\n"
        "print(json.dumps({'rc': rc, 'gc': gc.isenabled(), 'loaded': sorted(\n"
        "    m for m in mods if m in ('socket', 'pymodbus', 'scipy', 'filterpy', 'uuid')\n"
        "    or m.startswith('shoveld.cli.'))}))")
    assert got == {"rc": 0, "gc": True,  # the collector paused for the imports only
                   "loaded": ["shoveld.cli.common", "shoveld.cli.options", "shoveld.cli.replay",
                              "shoveld.cli.run"]}


def test_the_replay_program_ends_at_once_with_its_output_and_nothing_left(
        tmp_path: Path) -> None:
    """Run as the program, ``replay`` ends the process as soon as it returns: every line
    still reaches a pipe (block-buffered, no PYTHONUNBUFFERED), the status is the
    command's, and its temporary pass log is gone; a rejected command line still exits 2."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    env.update(PYTHONPATH=str(ROOT), TMPDIR=str(tmp_path))
    r = subprocess.run([sys.executable, "-m", "shoveld", "replay", str(CAPTURE), "--fast",
                        "--json", "--listen", f"tcp/127.0.0.1:{port}"],
                       capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    lines = [json.loads(x) for x in r.stdout.splitlines()]
    expected = json.loads((CAPTURE / "expected.json").read_text())["passes"]
    assert [m["payload_kg"] for m in lines if m["topic"] == "pass"] == [
        p["payload_kg"] for p in expected]
    assert lines[-1]["topic"] == "replay" and lines[-1]["capture_s"] > 100
    assert list(tmp_path.iterdir()) == []  # the temporary state folder was removed
    r = subprocess.run([sys.executable, "-m", "shoveld", "replay", str(CAPTURE), "--fast",
                        "--params", str(tmp_path / "none.toml")],
                       capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert r.returncode == 2 and "none.toml" in r.stderr
