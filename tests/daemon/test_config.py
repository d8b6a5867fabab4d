"""The configuration file: the example is valid, and every mistake names its key."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from shoveld.cli import main
from shoveld.daemon.config import ConfigError, check_params, load_config

from .conftest import PARAMS, ROOT

EXAMPLE = ROOT / "examples" / "shoveld.toml"


@pytest.fixture
def example(tmp_path: Path) -> Path:
    """The example config next to a params file, so it validates completely."""
    p = tmp_path / "shoveld.toml"
    shutil.copy(EXAMPLE, p)
    shutil.copy(PARAMS, tmp_path / "params.toml")
    return p


def edit(path: Path, old: str, new: str) -> Path:
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))
    return path


def test_example_config_is_valid(example: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = load_config(example)
    assert cfg.shovel_id == "shovel-07" and cfg.loop.rate_hz == 100.0
    assert cfg.params_path == example.parent / "params.toml"
    assert cfg.zenoh.mode == "client" and cfg.zenoh.connect
    assert cfg.engine.rate_hz == 100.0 and cfg.engine.truck_target_kg == 136000.0
    assert set(cfg.devices) == {"mti", "laser", "adc_motors", "adc_incl"}
    assert cfg.devices["mti"].max_age_s == 0.1
    assert "max_age_s" not in cfg.devices["mti"].driver  # daemon key, not the driver's
    assert cfg.devices["adc_incl"].signals == ("boom_deg", "roll_deg", "pitch_deg")
    check_params(cfg)
    assert main(["check-config", str(example)]) == 0
    out = capsys.readouterr().out
    assert "OK" in out and "adc_motors (modbus_tcp" in out


def test_defaults_peer_on_loopback(tmp_path: Path) -> None:
    text = EXAMPLE.read_text()
    head, rest = text.split("\n[zenoh]", 1)
    p = tmp_path / "c.toml"
    p.write_text(head.replace('"params.toml"', f'"{PARAMS}"') + "[installation]"
                 + rest.split("[installation]", 1)[1])
    cfg = load_config(p)
    assert cfg.zenoh.mode == "peer" and cfg.zenoh.listen == ("tcp/127.0.0.1:7447",)
    assert not cfg.zenoh.multicast_scouting


@pytest.mark.parametrize(("old", "new", "key"), [
    ("rate_hz = 100.0", "rate_hz = 0.5", "loop.rate_hz"),
    ("rate_hz = 100.0", 'rate_hz = "fast"', "loop.rate_hz"),
    ("max_age_s = 0.25", "max_age_seconds = 0.25", "loop.max_age_seconds"),
    ('id = "shovel-07"', 'id = "shovel/07"', "shovel.id"),
    ('mode = "client"', 'mode = "router2"', "zenoh.mode"),
    ('connect = ["tcp/10.20.0.2:7447", "tcp/10.20.0.3:7447"]', "connect = []", "zenoh.connect"),
    ('connect = ["tcp/10.20.0.2:7447",', 'connect = ["10.20.0.2:7447",', "zenoh.connect"),
    ("target_kg = 136000.0", "target_kg = -1", "truck.target_kg"),
    ("live_rate_hz = 10.0\n", 'live_rate_hz = 10.0\n[zenoh.config]\n"transport/bogus" = 3\n',
     "zenoh.config.transport/bogus"),
    ("crowd_offset_m = 5.88", "crowd_offset = 5.88", "installation.crowd_offset"),
    ("max_age_s = 0.1", "max_age_s = 0", "devices.mti.max_age_s"),
    ('kind = "mti_serial"', 'kind = "mti"', "devices.mti.kind"),
    ("rate_hz = 100\n", "rate_hz = 100\nbaud = 9600\n", "baud"),
    ('{ name = "hoist1_a", register = 0', '{ name = "hoist_1", register = 0', "hoist_1"),
    ('{ name = "hoist1_a", register = 0, scale = 400.0 },\n', "", "hoist1_a"),
    ('{ name = "boom_deg"', '{ name = "crowd_a"', "crowd_a"),
    # every driver refuses an unknown or missing key of its own table, by name
    ("sample_interval_us = 20000", "sample_interval = 20000",
     "[devices.laser]: ar4000: unknown key 'sample_interval'"),
    ('unit = 2\n', 'unit = 2\nslave = 2\n', "[devices.adc_incl]: modbus_tcp: unknown key 'slave'"),
    ('port = "/dev/serial/by-id/usb-Xsens_MTi_USB_converter-if00-port0"\n', "",
     "[devices.mti]: mti config: key 'port' is required"),
])
def test_bad_config_names_the_key(example: Path, old: str, new: str, key: str,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    edit(example, old, new)
    with pytest.raises(ConfigError, match=re.escape(key)):
        load_config(example)
    assert main(["check-config", str(example)]) == 2
    err = capsys.readouterr().err
    assert key in err and str(example) in err


def test_engine_sections_and_params_errors(example: Path) -> None:
    edit(example, "[zenoh]", "[engine]\nmin_samples = 30\nsettle_test_z = 0\n"
                             "[engine.phases]\ntuck_deg = -20.0\n"
                             "[engine.rls]\nprior_kg = 10000.0\n\n[zenoh]")
    cfg = load_config(example)
    assert cfg.engine.min_samples == 30 and cfg.engine.phases.tuck_deg == -20.0
    assert cfg.engine.settle_test_z == 0.0
    assert cfg.engine.rls.prior_kg == 10000.0
    edit(example, "tuck_deg = -20.0", "tuck = -20.0")
    with pytest.raises(ConfigError, match=r"engine\.phases\.tuck"):
        load_config(example)
    edit(example, "tuck = -20.0", "tuck_deg = -20.0")
    (example.parent / "params.toml").write_text("format = 'x'\n")
    cfg = load_config(example)
    with pytest.raises(ConfigError, match=r"shovel\.params"):
        check_params(cfg)


@pytest.mark.parametrize("section,line,key,why", [
    ("engine", "batch = 0", "engine.batch", "must be >= 1"),
    ("engine", "settle_s = -0.5", "engine.settle_s", "must be >= 0"),
    ("engine", "crowd_gap_s = 0", "engine.crowd_gap_s", "must be > 0"),
    ("engine", "doubt_factor = -2", "engine.doubt_factor", "must be >= 0"),
    ("engine", "empty_returns = 0", "engine.empty_returns", "must be >= 1"),
    ("engine", "weak_field_fraction = 1.5", "engine.weak_field_fraction", "must be <= 1"),
    ("engine.phases", "rise_deg_s = 0", "engine.phases.rise_deg_s", "must be > 0"),
    ("engine.phases", "tuck_deg = 10.0", "engine.phases.tuck_deg",
     "must be below 'dig_exit_deg'"),
    ("engine.phases", "swing_off_deg_s = 9.0", "engine.phases.swing_off_deg_s",
     "must be at most 'swing_on_deg_s'"),
    ("engine.rls", "prior_std_kg = 0", "engine.rls.prior_std_kg", "must be > 0"),
])
def test_an_engine_number_out_of_its_range_names_its_key(
        example: Path, section: str, line: str, key: str, why: str) -> None:
    """Until 2026-11-30 these were taken: a batch of no samples, a negative settle time, a
    crowd gap of 0 s (every tick a gap, every pass in doubt), a prior of no spread."""
    edit(example, "[zenoh]", f"[{section}]\n{line}\n\n[zenoh]")
    with pytest.raises(ConfigError, match=re.escape(f"key '{key}' {why}")):
        load_config(example)


def test_the_engine_ranges_keep_the_switches_off_at_zero(example: Path) -> None:
    """0 switches a check off where the docs say so (the empty dipper's, the crowd's
    doubt, the settle test, the crowd's travel): still taken."""
    edit(example, "[zenoh]", "[engine]\nempty_warn_kg = 0\ndoubt_factor = 0\n"
                             "settle_test_z = 0\nmin_crowd_travel_m = 0\n\n[zenoh]")
    cfg = load_config(example)
    assert (cfg.engine.empty_warn_kg, cfg.engine.doubt_factor, cfg.engine.settle_test_z,
            cfg.engine.min_crowd_travel_m) == (0.0, 0.0, 0.0, 0.0)


def test_run_refuses_to_start_with_a_bad_config(example: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    edit(example, "rate_hz = 100.0", "rate_hz = -3")
    assert main(["run", "--config", str(example)]) == 2
    err = capsys.readouterr().err
    assert "refusing to start" in err and "loop.rate_hz" in err


def test_unreadable_and_invalid_toml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.toml")
    p = tmp_path / "bad.toml"
    p.write_text("[shovel\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(p)


def test_check_config_says_when_the_calibrations_passes_fit_worse_than_its_trials(
        example: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A params file from ``calibrate --verified`` whose passes fit worse than its trials
    is usable, and check-config says what it lacks, as calibrate did and health will."""
    params = example.parent / "params.toml"
    for ratio, warned in (("hoist = 1.12\ncrowd = 1.03", False),
                          ("hoist = 2.57\ncrowd = 3.56", True)):
        shutil.copy(PARAMS, params)
        edit(params, "[fit.residual_rms]",
             f"[fit.passes_to_trials_rms]\n{ratio}\n\n[fit.residual_rms]")
        assert main(["check-config", str(example)]) == 0
        out = capsys.readouterr().out
        said = [x.strip() for x in out.splitlines() if "warning" in x]
        assert said == ([
            "warning: the calibration's passes fit worse than its trials (hoist 2.6, crowd "
            "3.6 times): above 1.5, the model lacks something this machine does in "
            "operation (a swing, a slope), which the misfit will not mark; shoveld "
            "diagnose names it"] if warned else []), out


def test_replay_takes_a_config_whose_devices_it_ignores(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``replay --config`` uses the capture's devices: the config's need not cover the
    payload (it was refused with the coverage's message), but a wrong key in them is
    still named, as it is wrong wherever the config is used. The daemon, which reads
    those devices, still refuses a config that does not cover the payload."""
    from .conftest import CAPTURE, free_port

    partial = tmp_path / "partial.toml"
    partial.write_text(f'[shovel]\nid = "x"\nparams = "{PARAMS}"\nstate_dir = "{tmp_path}"\n'
                       '[devices.laser]\nkind = "ar4000"\nport = "/dev/ttyUSB9"\n')
    argv = ["replay", str(CAPTURE), "--fast", "--until", "20", "--listen",
            f"tcp/127.0.0.1:{free_port()}", "--config"]
    assert main([*argv, str(partial)]) == 0, capsys.readouterr().err
    capsys.readouterr()
    with pytest.raises(ConfigError, match="no device provides"):
        load_config(partial)
    broken = tmp_path / "broken.toml"
    broken.write_text(partial.read_text().replace('port = "/dev/ttyUSB9"\n', ""))
    assert main([*argv, str(broken)]) == 2
    assert "[devices.laser]: ar4000: key 'port' is required" in capsys.readouterr().err
