"""The commands' numeric options: each has a range, and a value outside it is refused by
name before any work (``shoveld.cli.options``)."""

from __future__ import annotations

import argparse

import pytest

from shoveld.cli import SUBCOMMANDS, build_parser
from shoveld.cli.options import KEY_PREFIX, ORDER, SECONDS, SHOVEL_ID, SHOVEL_OR_ALL, number


def _parsers() -> list[tuple[str, argparse.ArgumentParser]]:
    """Every subcommand's parser (and a sub-subcommand's, as ``pki issue``)."""
    out = []
    todo = [("shoveld", build_parser())]
    while todo:
        name, p = todo.pop()
        out.append((name, p))
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                todo += [(f"{name} {k}", sp) for k, sp in a.choices.items()]
    return out


def test_every_subcommand_is_walked() -> None:
    names = {n.split()[1] for n, _ in _parsers() if len(n.split()) > 1}
    assert names == {s.replace("_", "-") for s in SUBCOMMANDS}


def test_no_numeric_option_takes_any_number() -> None:
    """A bare ``type=float`` takes ``nan``, ``inf`` and a negative duration; a bare
    ``int`` a negative seed, which numpy refused with a traceback (``sim --machine -3``).
    ``pki``'s ``--days`` is checked by the PKI itself, which names it
    (``tests/daemon/test_tls.py``)."""
    bare = sorted(f"{name} {'/'.join(a.option_strings)}" for name, p in _parsers()
                  for a in p._actions if a.type in (float, int))
    assert bare == ["shoveld pki init --days", "shoveld pki issue --days"]


@pytest.mark.parametrize("argv,expected", [
    (["sim", "--machine", "-3", "--out", "x.csv"], "--machine: '-3': expected a whole number "
                                                   "at least 0"),
    (["sim", "--load", "nan", "--out", "x.csv"], "--load: 'nan': expected a number at least 0 "
                                                 "(kg)"),
    (["replay", "cap", "--fast", "--until", "nan"], "--until: 'nan': expected a number above "
                                                    "0 (seconds)"),
    (["calibrate", "--out", "p.toml", "--polyorder", "1", "t.csv"],
     "--polyorder: '1': expected a whole number at least 2 and at most 20"),
    (["diagnose", "--calib", "a", "--measured", "b", "--alpha", "1"],
     "--alpha: '1': expected a number above 0 and below 1"),
    (["demo", "--port", "70000"], "--port: '70000': expected a whole number at least 1 and "
                                  "at most 65535"),
    (["pki", "router-config", "r", "--dir", "d", "--lease-s", "0.1"],
     "--lease-s: '0.1': expected a number at least 0.5 and at most 600 (seconds)"),
])
def test_a_number_out_of_range_is_refused_by_name(
        argv: list[str], expected: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as e:
        build_parser(argv[0]).parse_args(argv)
    assert e.value.code == 2
    assert expected in capsys.readouterr().err


def test_the_ranges_edges() -> None:
    assert SECONDS("0.5") == 0.5
    assert ORDER("2") == 2 and ORDER("20") == 20
    for bad in ("0", "-1", "nan", "inf", "-inf", "x", ""):
        with pytest.raises(argparse.ArgumentTypeError):
            SECONDS(bad)
    for bad in ("1", "21", "2.0", "3.5"):
        with pytest.raises(argparse.ArgumentTypeError):
            ORDER(bad)
    frac = number(0.0, 1.0, hi_open=True)
    assert frac("0") == 0.0
    with pytest.raises(argparse.ArgumentTypeError, match="at least 0 and below 1"):
        frac("1")


@pytest.mark.parametrize("argv,expected", [
    # a '/' in the id published under keys no cab reads, or another shovel's
    (["replay", "cap", "--fast", "--id", "a/b"], "--id: 'a/b': expected 1-64 letters"),
    (["replay", "cap", "--fast", "--id", "bad id!"], "--id: 'bad id!': expected 1-64"),
    (["cab", "--shovel", "a/b"], "--shovel: 'a/b': expected a shovel's id"),
    (["office", "--prefix", ""], "--prefix: '': expected a plain key expression"),
    (["cab", "--prefix", "x/**"], "--prefix: 'x/**': expected a plain key expression"),
    (["pki", "router-config", "r", "--dir", "d", "--prefix", "a//b"],
     "--prefix: 'a//b': expected a plain key expression"),
])
def test_a_key_word_that_is_not_one_is_refused_by_name(
        argv: list[str], expected: str, capsys: pytest.CaptureFixture[str]) -> None:
    """The words of Zenoh keys on the command line follow the config's rules for
    ``shovel.id`` and ``zenoh.prefix`` (until 2026-11-30, ``replay --id a/b`` and a
    screen's ``--prefix ''`` were taken)."""
    with pytest.raises(SystemExit) as e:
        build_parser(argv[0]).parse_args(argv)
    assert e.value.code == 2
    assert expected in capsys.readouterr().err


def test_the_key_words_edges() -> None:
    assert SHOVEL_ID("s-1.x_2") == "s-1.x_2" and SHOVEL_ID("x" * 64) == "x" * 64
    assert SHOVEL_OR_ALL("*") == "*" and KEY_PREFIX("site1/shovel") == "site1/shovel"
    for bad in ("", "x" * 65, "*", "a b", "a/b"):
        with pytest.raises(argparse.ArgumentTypeError):
            SHOVEL_ID(bad)
    for bad in ("**", "a*", ""):
        with pytest.raises(argparse.ArgumentTypeError):
            SHOVEL_OR_ALL(bad)
    for bad in ("/shovel", "shovel/", "a//b", "$*"):
        with pytest.raises(argparse.ArgumentTypeError):
            KEY_PREFIX(bad)
