"""Argument checking shared by ``skinet`` and the services: one-line errors, ranges, key names.

Every bad option value is refused by the parser itself, before any work starts,
with one line ``PROG: error: argument --budget: ...`` and exit status 2 (the
full usage text stays with ``--help``).  Values may come from environment
variables (argparse converts string defaults with the option's type), and the
message then names the variable.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from skinet.errors import Diagnostic, Pos, SkinetError, SourceError
from skinet.system.load import load_state, load_system, parse_state
from skinet.files.read import read_text
from skinet.system.model import Marking, System
from skinet.files.toml import locate, parse_toml
from skinet.wire.keys import check_chunk
from skinet.wire.limits import MAX_BUDGET, MIN_BUDGET


class ArgumentParser(argparse.ArgumentParser):
    """``argparse`` with a one-line error instead of the usage text (subparsers inherit it).

    ``intermixed=True`` (a subparser's keyword) lets its positionals come anywhere among its options, as
    :meth:`argparse.ArgumentParser.parse_intermixed_args` reads them: ``skinet goal SYSTEM -e ENDPOINT GOAL``
    (plain argparse gives the positionals one run: GOAL there was "unrecognized")."""

    def __init__(self, *args: object, intermixed: bool = False, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        # A dash then a digit is a value, not an option: `--memory-limit -5MiB` reaches the option's own check
        # (argparse takes only plain negative numbers as values, and said "expected one argument").
        self._negative_number_matcher = re.compile(r"^-\.?\d")
        self._intermixed = intermixed
        self._within = False  # parse_known_intermixed_args calls parse_known_args twice: those are plain

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[no-untyped-def]
        if not self._intermixed or self._within:
            return super().parse_known_args(args, namespace)
        self._within = True
        try:
            return self.parse_known_intermixed_args(args, namespace)
        except AttributeError as exc:
            # Ctrl-C inside Python 3.11's parse_known_intermixed_args breaks its clean-up (``save_nargs`` not
            # set yet), which raises AttributeError over the KeyboardInterrupt: give the caller the Ctrl-C.
            if isinstance(exc.__context__, KeyboardInterrupt):
                raise exc.__context__ from None
            raise
        finally:
            self._within = False

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _number(kind: Callable[[str], float], what: str, low: float | None, low_open: bool,
            high: float | None, env: str | None) -> Callable[[str], float]:
    def convert(text: str) -> float:
        try:
            value = kind(text)
        except (TypeError, ValueError):
            value = None
        ok = value is not None and math.isfinite(value)
        if ok and low is not None:
            ok = value > low if low_open else value >= low
        if ok and high is not None:
            ok = value <= high
        if not ok:
            origin = f" (from ${env})" if env and os.environ.get(env) == text else ""
            raise argparse.ArgumentTypeError(f"expected {what}, got '{text}'{origin}")
        return value  # type: ignore[return-value]

    convert.__name__ = what  # argparse names the type in some messages
    return convert


def seconds(env: str | None = None, zero: bool = False) -> Callable[[str], float]:
    """A finite duration in seconds, > 0 (>= 0 with ``zero``)."""
    what = "a number of seconds >= 0" if zero else "a number of seconds > 0"
    return _number(float, what, 0.0, not zero, None, env)


def seconds_within(low: float, high: float, env: str | None = None) -> Callable[[str], float]:
    """A duration in seconds in ``[low, high]``."""
    return _number(float, f"a number of seconds from {low:g} to {high:g}", low, False, high, env)


def budget(env: str | None = None) -> Callable[[str], float]:
    """A prediction budget in seconds: at least the predictor's minimum (docs/semantics.md §6.1), at most one day."""
    return _number(float, f"a number of seconds from {MIN_BUDGET:g} (the predictor's minimum budget) to "
                          f"{MAX_BUDGET:g} (one day)", MIN_BUDGET, False, MAX_BUDGET, env)


def time_budget(env: str | None = None) -> Callable[[str], float]:
    """An exploration or planning budget in seconds: > 0, at most one day (``MAX_BUDGET``)."""
    return _number(float, f"a number of seconds > 0 and at most {MAX_BUDGET:g} (one day)", 0.0, True, MAX_BUDGET,
                   env)


def add_outcome_timeout_arg(parser: argparse.ArgumentParser) -> None:
    """The pilot's ``--outcome-timeout S`` (docs/pilot.md, *Missed outcomes*)."""
    from skinet.wire.limits import PILOT_OUTCOME_TIMEOUT

    parser.add_argument("--outcome-timeout", type=seconds(), default=PILOT_OUTCOME_TIMEOUT, metavar="S",
                        help="seconds a skill the pilot started may run without an outcome before the pilot asks "
                             f"its manager for its status, and again after as long (default: {PILOT_OUTCOME_TIMEOUT:g})")


def number(low: float, env: str | None = None) -> Callable[[str], float]:
    """A finite number >= ``low``."""
    return _number(float, f"a number >= {low:g}", low, False, None, env)


def count(low: int = 1, high: int | None = None, env: str | None = None) -> Callable[[str], int]:
    """An integer in ``[low, high]``."""
    what = f"an integer >= {low}" if high is None else f"an integer from {low} to {high}"
    return _number(int, what, low, False, high, env)  # type: ignore[return-value]


def probability(env: str | None = None) -> Callable[[str], float]:
    """A probability: a number from 0 to 1."""
    return _number(float, "a probability from 0 to 1", 0.0, False, 1.0, env)


# The options of a simulated robot whose skills end by themselves: (name, environment variable, default).
SELF_ENDING = (("skill_duration", "SKINET_SKILL_DURATION", 1.0), ("failure_rate", "SKINET_FAILURE_RATE", 0.0),
               ("seed", None, 0))


def add_self_ending_args(parser: argparse.ArgumentParser, flag: str) -> None:
    """The options of a simulated robot whose skills end by themselves (``flag``: the option that asks for it;
    docs/pilot.md, *Try the pilot in one command*); :func:`self_ending_options` reads them."""
    g = parser.add_argument_group(f"the simulated robot's skills (with {flag})")
    g.add_argument("--skill-duration", type=seconds(zero=True), metavar="S",
                   help="seconds each skill runs before it ends by itself (default: $SKINET_SKILL_DURATION, else 1)")
    g.add_argument("--failure-rate", type=probability(), metavar="P",
                   help="probability that a run of a skill ends in one of its failure modes (drawn with --seed) "
                        "instead of its first success mode (default: $SKINET_FAILURE_RATE, else 0)")
    g.add_argument("--seed", type=count(0), metavar="N",
                   help="seed of the failure draws: the same seed gives the same outcomes in the same order of "
                        "starts (default: 0)")


def self_ending_options(args: argparse.Namespace, flag: str, on: bool) -> tuple[float, float, int]:
    """(skill duration, failure rate, seed) of :func:`add_self_ending_args`: the option, else its environment
    variable (checked by :mod:`services.common.environment` before any command starts), else the default.
    Raises :class:`SelfEndingMisused` when one of them is given while ``on`` is false (``flag`` not given)."""
    given = [name for name, _, _ in SELF_ENDING if getattr(args, name, None) is not None]
    if given and not on:
        raise SelfEndingMisused(f"--{given[0].replace('_', '-')} needs {flag}")
    values = []
    for name, env, default in SELF_ENDING:
        value = getattr(args, name, None)
        if value is None:
            value = type(default)(float(os.environ[env])) if env and os.environ.get(env) else default
        values.append(value)
    return values[0], values[1], values[2]  # type: ignore[return-value]


class SelfEndingMisused(SkinetError):
    """An option of the simulated robot's skills without the option that asks for that robot."""


def key_name(what: str) -> Callable[[str], str]:
    """A Zenoh key chunk (system names, instance ids): letters, digits, ``_ - .``."""
    def convert(text: str) -> str:
        try:
            return check_chunk(text, what)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return convert


def key_prefix(what: str, env: str | None = None) -> Callable[[str], str]:
    """Empty, or ``/``-separated Zenoh key chunks (a ROS namespace such as ``/robot1``)."""
    def convert(text: str) -> str:
        try:
            for chunk in text.strip("/").split("/") if text.strip("/") else ():
                check_chunk(chunk, what)
        except ValueError:
            origin = f" (from ${env})" if env and os.environ.get(env) == text else ""
            raise argparse.ArgumentTypeError(f"{what} '{text}'{origin} cannot be used in a Zenoh key "
                                             "(/-separated names of letters, digits, _ - .)")
        return text

    return convert


_NAME_LINE = re.compile(r'^\s*name\s*=\s*(["\'])')


def load_live_system(path: str | Path) -> tuple[System, list[Diagnostic]]:
    """:func:`skinet.system.load.load_system`, refusing a system name that cannot be a Zenoh key chunk.

    Every command takes the name as the ``<system>`` of ``skinet/<system>/...``
    keys, so ``skinet unsafe`` refuses what ``skinet run`` could not publish.
    """
    system, warnings = load_system(path)
    try:
        check_chunk(system.name, "system name")
    except ValueError as exc:
        raise SourceError.at(str(path), _name_pos(path), str(exc)) from None
    return system, warnings


def add_no_properties_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-properties", action="store_true",
                        help="accept a system without safety properties (by default refused: nothing would ever be "
                             "reported unsafe)")


def require_properties(system: System, path: str | Path, allowed: bool) -> None:
    """Refuse a system without safety properties unless ``allowed`` (``--no-properties``).

    A monitor with no property reports every command safe: run on purpose, or
    because ``properties`` was left out of the system file, it would vouch for
    everything.
    """
    if system.properties or allowed:
        return
    text = read_text(path)
    data = parse_toml(text, str(path))
    named = data["system"].get("properties") if isinstance(data.get("system"), dict) else None
    why = (f"{named} defines none" if named is not None
           else "its [system] table names no properties file (properties = \"FILE.props\")")
    raise SourceError.at(str(path), locate(text, ("system",), "properties") or locate(text, ("system",)),
                         f"system '{system.name}' has no safety properties: {why}; nothing would ever be reported "
                         "unsafe (--no-properties runs it anyway)")


def _name_pos(path: str | Path) -> Pos | None:
    """Where ``name = "..."`` is written in the ``[system]`` table, if found."""
    table = ""
    for n, line in enumerate(read_text(path).splitlines(), 1):
        stripped = line.strip()
        if stripped.startswith("["):
            table = stripped
        elif table == "[system]" and (m := _NAME_LINE.match(line)):
            return Pos(n, m.start(1) + 1)
    return None


def state_marking(state: str, system: System, what_if: bool = False) -> tuple[Marking, str]:
    """The marking ``--state`` gives, a JSON file or the JSON itself, and its source name for errors.

    A marking the robot cannot be in is refused unless ``what_if`` (:func:`skinet.system.load.parse_state`).
    """
    if state.lstrip().startswith("{"):  # the JSON itself
        return parse_state(state, "<state>", system, what_if), "<state>"
    return load_state(state, system, what_if), state


def print_warnings(warnings: list[Diagnostic]) -> None:
    for w in warnings:
        print(str(w), file=sys.stderr)
