"""Every command and service entry point, with a bad value for each of its options.

Each case must end with exactly one line on standard error (the expected one),
the expected exit status (2: refused by the argument parser, 1: refused while
running), nothing on standard output and no traceback.  A coverage test checks
that every option taking a value, of every ``skinet`` command and every
``python -m services.*`` entry point, has at least one case here (or is listed
in FREE_TEXT with the reason why no value is bad).  The cases run in-process;
a few run as real processes too, to show the entry points themselves.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

import services.bridge_ros2.__main__ as bridge_main
import services.monitor.__main__ as monitor_main
import services.pilot.__main__ as pilot_main
import services.predictor.__main__ as predictor_main
import services.simulator.__main__ as simulator_main
import skinet_cli.main as skinet_main

ROOT = Path(__file__).resolve().parents[2]
SYSTEM = str(ROOT / "skillsets" / "spot_arm.toml")
SCENARIO = str(ROOT / "skillsets" / "missions" / "unassisted.toml")
SPOT = str(ROOT / "skillsets" / "spot.rl")

# program -> (main, argument parser factory)
PROGRAMS: dict[str, tuple[Callable[..., int], Callable[[], argparse.ArgumentParser]]] = {
    "skinet": (skinet_main.main, skinet_main.build_parser),
    "python -m services.monitor": (monitor_main.main, monitor_main.build_parser),
    "python -m services.predictor": (predictor_main.main, predictor_main.build_parser),
    "python -m services.bridge_ros2": (bridge_main.main, bridge_main.build_parser),
    "python -m services.simulator": (simulator_main.main, simulator_main.build_parser),
    "python -m services.pilot": (pilot_main.main, pilot_main.build_parser),
}

# Options where every value is acceptable (nothing to refuse).
FREE_TEXT = {
    ("skinet timeline", "--title"): "any text is a title (test_any_title_is_drawn)",
    ("python -m services.bridge_ros2", "--source"): "any text names the source inside the events' payload",
    **{(program, "--ros-distro"): "only humble changes the keys; any other name is a later one"
       for program in ("python -m services.bridge_ros2", "python -m services.simulator", "skinet run", "skinet rosbag",
                       "python -m services.pilot")},
    **{(program, option): "any user name and password is sent; the router judges them (tests/deploy/test_operator_acl.py)"
       for program in ("skinet record", "skinet rosbag", "skinet foxglove", "skinet replay", "skinet run", "skinet router", "skinet watch", "skinet check",
                       "skinet goal",
                       "skinet demo",
                       "skinet dashboard", "python -m services.monitor", "python -m services.predictor",
                       "python -m services.bridge_ros2", "python -m services.simulator",
                       "python -m services.pilot")
       for option in ("--user", "--password")},
    ("skinet router", "--secrets"): "any folder: made at first start when missing (test_security.py)",
    ("skinet fleet", "--secrets"): "any folder: made at first start when missing (test_security.py)",
}


@dataclass(frozen=True)
class Case:
    program: str  # a key of PROGRAMS
    option: str  # the option (or positional dest) the case is about
    argv: tuple[str, ...]
    code: int
    error: str  # the one line expected on standard error; {tmp} and {port} are filled in
    env: tuple[tuple[str, str], ...] = ()

    @property
    def command(self) -> str:
        """``skinet unsafe`` for skinet's subcommands, the program otherwise."""
        return f"skinet {self.argv[0]}" if self.program == "skinet" else self.program

    def __str__(self) -> str:
        env = " ".join(f"{k}={v}" for k, v in self.env)
        return f"{env + ' ' if env else ''}{self.command} {self.option}: {' '.join(self.argv)}"[:120]


def _usage(command: str, message: str) -> str:
    return f"{command}: error: {message} (see {command} --help)"


def _cases() -> list[Case]:
    cases: list[Case] = []

    def add(program: str, option: str, argv: tuple[str, ...], code: int, error: str, **env: str) -> None:
        cases.append(Case(program, option, argv, code, error, tuple(env.items())))

    def usage(program: str, option: str, argv: tuple[str, ...], message: str, **env: str) -> None:
        command = f"skinet {argv[0]}" if program == "skinet" else program
        add(program, option, argv, 2, _usage(command, message), **env)

    def live_options(base: tuple[str, ...]) -> None:
        """The options of a real-time play served to other processes (skinet demo --live, skinet replay:
        skinet_cli.live_demo.add_live_args), bad values after ``base``."""
        for bad in ("-1", "fast"):
            usage("skinet", "--speed", (*base, "--speed", bad),
                  f"argument --speed: expected a number >= 0, got '{bad}'")
        usage("skinet", "--linger", (*base, "--linger", "-1"), "argument --linger: expected a number of seconds >= 0, "
                                                                "got '-1'")
        usage("skinet", "--dashboard", (*base, "--dashboard", "65536"),
              "argument --dashboard: expected an integer from 0 to 65535, got '65536'")
        add("skinet", "--dashboard-host", (*base, "--no-multicast-scouting", "--dashboard", "0", "--dashboard-host",
                                           "999.0.0.1"), 1,
            "skinet: error: cannot listen on 999.0.0.1:0: Name or service not known")

    missing = "{tmp}/missing.toml: error: cannot read file: No such file or directory"
    bad_name = ("{tmp}/badname.toml:2:8: error: system name 'has space/slash' cannot be used in a Zenoh key "
                "(letters, digits, _ - . only)")
    seconds = "expected a number of seconds > 0, got '{}'"
    budget = "expected a number of seconds from 0.05 (the predictor's minimum budget) to 86400 (one day), got '{}'"
    time_budget = "expected a number of seconds > 0 and at most 86400 (one day), got '{}'"

    # skinet parse / net
    add("skinet", "file", ("parse", "{tmp}/missing.rl"), 1,
        "{tmp}/missing.rl: error: cannot read file: No such file or directory")
    add("skinet", "file", ("parse", SYSTEM), 1,
        f"{SYSTEM}: error: this is a system or scenario file (.toml); skinet parse checks a skillset model (.rl): "
        f"for a system try skinet net {SYSTEM} or skinet unsafe {SYSTEM}")
    add("skinet", "file", ("net", "{tmp}/missing.rl"), 1,
        "{tmp}/missing.rl: error: cannot read file: No such file or directory")
    usage("skinet", "--format", ("net", SPOT, "--format", "svg"),
          "argument --format: invalid choice: 'svg' (choose from 'dot', 'json', 'pnml', 'promela', 'tina')")
    add("skinet", "-o", ("net", SPOT, "-o", "{tmp}/no/such/net.json"), 1,
        "{tmp}/no/such/net.json: error: cannot write file: No such file or directory")

    # skinet unsafe / explore / ctl: the same system options
    for cmd in ("unsafe", "explore", "ctl"):
        extra = ("EF spot:Busy",) if cmd == "ctl" else ()
        add("skinet", "system", (cmd, "{tmp}/missing.toml", *extra), 1, missing)
        add("skinet", "system", (cmd, "{tmp}/badname.toml", *extra), 1, bad_name)
        add("skinet", "--state", (cmd, SYSTEM, "--state", "{tmp}/missing.json", *extra), 1,
            "{tmp}/missing.json: error: cannot read file: No such file or directory")
        # Past one day a deadline would mean "never" (issue 30): 1e308 is refused, not clamped.
        for bad in ("-5", "0", "nan", "inf", "soon", "1e308", "86400.5"):
            usage("skinet", "--budget", (cmd, SYSTEM, "--budget", bad, *extra),
                  "argument --budget: " + time_budget.format(bad))
        for bad in ("-1", "1.5"):
            usage("skinet", "--max-depth", (cmd, SYSTEM, "--max-depth", bad, *extra),
                  f"argument --max-depth: expected an integer >= 0, got '{bad}'")
        usage("skinet", "--af", (cmd, SYSTEM, "--af", "strict", *extra),
              "argument --af: invalid choice: 'strict' (choose from 'fair', 'literal')")
        for bad in ("0", "lots", "1 parsec"):
            usage("skinet", "--memory-limit", (cmd, SYSTEM, "--memory-limit", bad, *extra),
                  f"argument --memory-limit: not a size: '{bad}' (e.g. 1GiB, 512MiB, 2GB)")
        for argv in (("--memory-limit", "-5MiB"), ("--memory-limit=-5MiB",)):  # the first was "expected one argument"
            usage("skinet", "--memory-limit", (cmd, SYSTEM, *argv, *extra),
                  "argument --memory-limit: not a size: '-5MiB' (a size is positive, e.g. 1GiB, 512MiB, 2GB)")
        add("skinet", "--state", (cmd, SYSTEM, "--state", '{"spot": ', *extra), 1,
            "<state>:1:10: error: invalid JSON: Expecting value")
    add("skinet", "formulas", ("ctl", SYSTEM, "EF spot:Busy", "EF spot:Bussy"), 1,
        "<formula 2>:1:4: error: unknown name 'spot:Bussy' (candidates: spot:Busy)")

    # skinet plan (issue 23): bad goals, goal files, inputs and states, each one line with its place
    add("skinet", "system", ("plan", "{tmp}/missing.toml", "reach spot:Busy"), 1, missing)
    add("skinet", "system", ("plan", "{tmp}/badname.toml", "reach spot:Busy"), 1, bad_name)
    for goal, error in (
        ("run spt:teleop", "<goal>:1:5: error: unknown skillset 'spt' (candidates: spot)"),
        ("run spot:telop", "<goal>:1:10: error: unknown skill 'telop' of 'spot' (candidates: teleop)"),
        ("run spot:teleop.success.finished", "<goal>:1:25: error: unknown success mode 'finished' of 'spot:teleop' "
                                             "(expected one of: done)"),
        ("run spot:teleop.failure.link_lost", "<goal>:1:17: error: unexpected 'failure', expected 'success'"),
        ("reach spot:Stnding", "<goal>:1:7: error: unknown name 'spot:Stnding' (candidates: spot:Standing, "
                               "spot:Sitting, spot:posture.Standing)"),
        ("reach (spot:Busy and", "<goal>:1:21: error: unexpected end of input, expected one of: '(', 'false', "
                                 "'not', 'true', identifier"),
        ("reach EF spot:Busy", "<goal>:1:7: error: reach takes a state formula (atoms, not, and, or, =>), "
                               "not a temporal operator"),
        ("fly spot:Busy", "<goal>:1:1: error: unexpected 'fly', expected one of: 'reach', 'run'"),
        ("run spot:go_to_waypoint", "<goal>:1:5: error: run spot:go_to_waypoint needs input 'target' (GeoPoint): "
                                    "give it with --inputs, e.g. --inputs 'go_to_waypoint.target = ...'"),
    ):
        add("skinet", "goals", ("plan", SYSTEM, goal), 1, error)
    add("skinet", "goals", ("plan", SYSTEM, "reach spot:Busy", "reach manipulator:Bussy"), 1,
        "<goal 2>:1:7: error: unknown name 'manipulator:Bussy' (candidates: manipulator:Busy)")
    add("skinet", "goals", ("plan", SYSTEM), 1,
        'skinet: error: no goals: give GOAL arguments (e.g. "reach spot:Standing") or --goals FILE')
    add("skinet", "--goals", ("plan", SYSTEM, "--goals", "{tmp}/missing.toml"), 1, missing)
    for name, error in (
        ("empty", "1:1: error: no goals: a goals file lists [[goals]] tables, each with reach = \"FORMULA\" or "
                  "run = \"SKILLSET:SKILL\""),
        ("syntax", "3:4: error: invalid TOML: Expected '=' after a key in a key/value pair"),
        ("top_key", "1:1: error: unknown key 'goal' at the top level (keys belong in a table) (candidates: [[goals]])"),
        ("goal_key", "6:1: error: unknown key 'input' in [[goals]] (candidates: inputs)"),
        ("both", "3:1: error: goal 1 has both reach and run"),
        ("neither", "1:1: error: goal 1 needs reach = \"FORMULA\" or run = \"SKILLSET:SKILL\""),
        ("formula", "5:28: error: unknown name 'spot:Bussy' (candidates: spot:Busy)"),
        ("not_string", "2:1: error: goal 1: reach must be a string"),
        ("input_type", "3:31: error: input 'target' of spot:go_to_waypoint (GeoPoint): expected a table of the fields "
                       "of geometry_msgs/msg/Point, got a string"),
        ("input_field", "3:31: error: input 'target' of spot:go_to_waypoint (GeoPoint): expected float64 at y, "
                        "got a string"),
        ("input_name", "3:31: error: unknown input 'goal' of spot:go_to_waypoint (expected one of: target)"),
        ("input_skill", "3:12: error: unknown skill 'go_to_waypont' (candidates: go_to_waypoint, spot:go_to_waypoint)"),
        ("input_missing", "2:8: error: run spot:go_to_waypoint needs input 'target' (GeoPoint): give it in the goal's "
                          "inputs, e.g. inputs = { go_to_waypoint = { target = ... } }"),
    ):
        add("skinet", "--goals", ("plan", SYSTEM, "--goals", f"{{tmp}}/goals_{name}.toml"), 1,
            f"{{tmp}}/goals_{name}.toml:{error}")
    add("skinet", "--inputs", ("plan", SYSTEM, "run spot:go_to_waypoint", "--inputs", "go_to_waypoint.target = {x = \"far\"}"),
        1, "<--inputs>:1:16: error: input 'target' of spot:go_to_waypoint (GeoPoint): expected float64 at x, got a string")
    add("skinet", "--inputs", ("plan", SYSTEM, "reach spot:Busy", "--inputs", "target ="), 1,
        "<--inputs>:1:9: error: invalid TOML: Invalid value")
    add("skinet", "--state", ("plan", SYSTEM, "reach spot:Busy", "--state", "{tmp}/missing.json"), 1,
        "{tmp}/missing.json: error: cannot read file: No such file or directory")
    add("skinet", "--state", ("plan", SYSTEM, "reach spot:Busy", "--state", "{tmp}/impossible.json"), 1,
        "{tmp}/impossible.json: error: impossible state: 'spot' is not stable: invariant violated (stand_up.inv.powered);"
        " the manager never publishes such a state")
    add("skinet", "--state", ("plan", SYSTEM, "reach spot:Busy", "--state", '{"spot": {"running": ["stand_up"]}}'), 1,
        "<state>: error: impossible state: 'spot' is not stable: invariant violated (stand_up.inv.powered); the manager "
        "never publishes such a state")
    for bad in ("0", "-1", "never", "1e308"):
        usage("skinet", "--budget", ("plan", SYSTEM, "reach spot:Busy", "--budget", bad),
              "argument --budget: " + time_budget.format(bad))
    usage("skinet", "--memory-limit", ("plan", SYSTEM, "reach spot:Busy", "--memory-limit", "much"),
          "argument --memory-limit: not a size: 'much' (e.g. 1GiB, 512MiB, 2GB)")
    usage("skinet", "--engine", ("plan", SYSTEM, "reach spot:Busy", "--engine", "fast"),
          "argument --engine: invalid choice: 'fast' (choose from 'auto', 'explicit', 'symbolic')")

    # skinet goal (issue 24 item 4): checked as skinet plan checks them when the system file is given, before
    # any connection; with a system name the pilot checks them (tests/services/test_goal.py).  A malformed goal
    # is a rejected one: exit 2, as its --help says (issue 32 item 8); a file that cannot be read, 1.
    add("skinet", "system", ("goal", "{tmp}/missing.toml", "reach spot:Busy"), 1, missing)
    add("skinet", "system", ("goal", "{tmp}/badname.toml", "reach spot:Busy"), 1, bad_name)
    add("skinet", "system", ("goal", "a/b", "reach spot:Busy"), 1,
        "skinet: error: system name 'a/b' cannot be used in a Zenoh key (letters, digits, _ - . only)")
    add("skinet", "goals", ("goal", SYSTEM, "reach spot:Stnding"), 2,
        "<goal>:1:7: error: unknown name 'spot:Stnding' (candidates: spot:Standing, spot:Sitting, spot:posture.Standing)")
    add("skinet", "goals", ("goal", SYSTEM, "reach spot:Busy", "reach manipulator:Bussy"), 2,
        "<goal 2>:1:7: error: unknown name 'manipulator:Bussy' (candidates: manipulator:Busy)")
    add("skinet", "goals", ("goal", "spot_arm"), 2,
        'skinet: error: no goals: give GOAL arguments (e.g. "reach spot:Standing") or --goals FILE (or --cancel, '
        "--pause, --resume, --set-mode, --confirm for the goal that runs)")
    add("skinet", "goals", ("goal", "spot_arm", "--cancel", "--inputs", "x = 1"), 2,
        "skinet: error: --cancel takes no goals: it acts on the goal that runs")
    add("skinet", "--goals", ("goal", SYSTEM, "--goals", "{tmp}/missing.toml"), 1, missing)
    add("skinet", "--goals", ("goal", SYSTEM, "--goals", "{tmp}/goals_formula.toml"), 2,
        "{tmp}/goals_formula.toml:5:28: error: unknown name 'spot:Bussy' (candidates: spot:Busy)")
    add("skinet", "--inputs", ("goal", "spot_arm", "reach spot:Busy", "--inputs", "target ="), 2,
        "<--inputs>:1:9: error: invalid TOML: Invalid value")
    add("skinet", "--inputs", ("goal", SYSTEM, "run spot:go_to_waypoint", "--inputs",
                               "go_to_waypoint.target = {x = \"far\"}"), 2,
        "<--inputs>:1:16: error: input 'target' of spot:go_to_waypoint (GeoPoint): expected float64 at x, got a string")
    usage("skinet", "--max-retries", ("goal", "spot_arm", "reach spot:Busy", "--max-retries", "0"),
          "argument --max-retries: expected an integer from 1 to 100, got '0'")
    usage("skinet", "--set-mode", ("goal", "spot_arm", "--set-mode", "fly"),
          "argument --set-mode: invalid choice: 'fly' (choose from 'guide', 'drive')")
    usage("skinet", "--confirm", ("goal", "spot_arm", "--confirm", "maybe"),
          "argument --confirm: invalid choice: 'maybe' (choose from 'success', 'failure', 'rerun')")
    add("skinet", "--confirm", ("goal", "spot_arm", "--confirm", "success", "--pause"), 2,
        "skinet goal: error: argument --pause: not allowed with argument --confirm (see skinet goal --help)")
    add("skinet", "--set-mode", ("goal", "spot_arm", "reach spot:Busy", "--set-mode", "drive"), 2,
        "skinet: error: --set-mode takes no goals: it acts on the goal that runs")
    add("skinet", "--interrupt", ("goal", "spot_arm", "--pause", "--interrupt"), 2,
        "skinet: error: --interrupt goes with --cancel: it interrupts what the cancelled goal started")
    usage("skinet", "--timeout", ("goal", "spot_arm", "reach spot:Busy", "--timeout", "0"),
          "argument --timeout: " + seconds.format("0"))

    # skinet demo
    add("skinet", "scenarios", ("demo", "{tmp}/missing.toml"), 1, missing)
    add("skinet", "scenarios", ("demo", "{tmp}/unknown_skillset.toml"), 1,
        "{tmp}/unknown_skillset.toml:6:1: error: step 1: unknown skillset 'spott' (skillsets of spot_arm: spot, manipulator)")
    for core in ((), ("--core",)):  # the core replay used to call it a model divergence and exit 0
        add("skinet", "scenarios", ("demo", "{tmp}/unknown_transition.toml", *core), 1,
            "{tmp}/unknown_transition.toml:7:1: error: step 1: unknown transition 'init_power.strat' of skillset 'spot' "
            "(for example: init_power.start, init_power.interrupt, init_power.success.powered_on, "
            "init_power.failure.no_battery)")
    add("skinet", "scenarios", ("demo", "{tmp}/bad_time.toml", "--core"), 1,
        "{tmp}/bad_time.toml:5:1: error: step 1: 't' must be a number of seconds, got 'soon'")
    for option in ("--log", "--timeline"):
        add("skinet", option, ("demo", "--core", option, "{tmp}/list.json"), 1,
            "{tmp}/list.json: error: cannot create folder: File exists")
    live_options(("demo", "--live"))

    # skinet record, run, router, and every service: the Zenoh options
    zenoh_programs = {
        "skinet": (("record", "spot_arm", "-o", "{tmp}/rec.jsonl", "--duration", "1"),
                   ("rosbag", SYSTEM, "-o", "{tmp}/bag", "--duration", "0.5"),
                   ("run", SYSTEM, "--once"), ("router",), ("watch", "spot_arm", "--wait", "0.5"),
                   ("check", "spot_arm", "spot:teleop.start", "--timeout", "0.5"),
                   ("goal", "spot_arm", "reach spot:Busy", "--timeout", "0.5"),
                   ("dashboard", "spot_arm", "--port", "0", "--wait", "0"),
                   ("foxglove", "spot_arm", "--port", "0", "--wait", "0"),
                   ("replay", "{tmp}/run.jsonl", "--linger", "0"), ("demo", "--live", "--linger", "0")),
        "python -m services.monitor": ((SYSTEM,),),
        "python -m services.predictor": ((),),
        "python -m services.bridge_ros2": ((SYSTEM,),),
        "python -m services.simulator": ((SCENARIO,),),
        "python -m services.pilot": ((SYSTEM,),),
    }
    for program, bases in zenoh_programs.items():
        for base in bases:
            prefix = "skinet: error: " if program == "skinet" else f"{program}: error: "
            if base[:1] != ("run",) and base[:1] != ("router",):
                usage(program, "--mode", (*base, "--mode", "server"),
                      "argument --mode/-m: invalid choice: 'server' (choose from 'peer', 'client', 'router')")
            add(program, "--listen", (*base, "--listen", "garbage"), 1,
                prefix + "--listen 'garbage': an endpoint is PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447")
            add(program, "--listen", (*base, "--listen", "tcp/1.2.3.4:99999"), 1,
                prefix + "--listen 'tcp/1.2.3.4:99999': port '99999' is not a number from 0 to 65535")
            add(program, "--listen", (*base, "--listen", "tcp/127.0.0.1:notaport"), 1,
                prefix + "--listen 'tcp/127.0.0.1:notaport': port 'notaport' is not a number from 0 to 65535")
            add(program, "--listen", (*base, "--no-multicast-scouting", "--listen", "tcp/127.0.0.1:{port}"), 1,
                prefix + "cannot open the Zenoh session: cannot listen on tcp/127.0.0.1:{port}: address already in use")
            add(program, "--connect", (*base, "--connect", "tcp/127.0.0.1"), 1,
                prefix + "--connect 'tcp/127.0.0.1': the address must be HOST:PORT, e.g. tcp/127.0.0.1:7447")
            add(program, "--zenoh-config", (*base, "--zenoh-config", "{tmp}/missing.json5"), 1,
                "{tmp}/missing.json5: error: cannot read file: No such file or directory")
            add(program, "--password-file", (*base, "--no-multicast-scouting", "--password-file", "{tmp}/missing.pw"),
                1, prefix + "cannot read password file {tmp}/missing.pw: No such file or directory")
            add(program, "--zenoh-config", (*base, "--zenoh-config", "{tmp}/bad.json5"), 1,
                "{tmp}/bad.json5:2:3: error: invalid Zenoh configuration: unknown field `mood`, expected one of "
                "`id`, `metadata`, `mode`, `region_name`, `gateway`, `connect`, `listen`, `open`, `scouting`, "
                "`timestamping`, `queries_default_timeout`, `routing`, `aggregation`, `qos`, `transport`, "
                "`adminspace`, `namespace`, `downsampling`, `access_control`, `low_pass_filter`, `stats`, "
                "`plugins_loading`, `plugins`")
            add(program, "--zenoh-config", (*base, "--zenoh-config", "{tmp}/syntax.json5"), 1,
                "{tmp}/syntax.json5:1:1: error: invalid Zenoh configuration: expected array, boolean, null, number, "
                "object, or string")
            if base[:1] != ("run",) and base[:1] != ("router",):
                add(program, "--mode", base, 1, prefix + "SKINET_ZENOH_MODE 'server' is not one of peer, client, router",
                    SKINET_ZENOH_MODE="server")
                add(program, "--connect", base, 1,
                    prefix + "SKINET_ZENOH_CONNECT 'nowhere': an endpoint is PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447",
                    SKINET_ZENOH_CONNECT="nowhere")
                add(program, "--zenoh-config", base, 1,
                    "{tmp}/missing.json5: error: cannot read file: No such file or directory",
                    SKINET_ZENOH_CONFIG="{tmp}/missing.json5")

    usage("skinet", "system", ("record", "a/b", "-o", "{tmp}/rec.jsonl"),
          "argument SYSTEM_NAME: system name 'a/b' cannot be used in a Zenoh key (letters, digits, _ - . only)")
    add("skinet", "-o", ("record", "spot_arm", "--no-multicast-scouting", "-o", "{tmp}/no/such/rec.jsonl"), 1,
        "{tmp}/no/such/rec.jsonl: error: cannot write file: No such file or directory")
    usage("skinet", "--duration", ("record", "spot_arm", "-o", "{tmp}/rec.jsonl", "--duration", "-1"),
          "argument --duration: " + seconds.format("-1"))
    usage("skinet", "--count", ("record", "spot_arm", "-o", "{tmp}/rec.jsonl", "--count", "0"),
          "argument --count: expected an integer >= 1, got '0'")

    add("skinet", "system", ("rosbag", "{tmp}/missing.toml", "-o", "{tmp}/bag"), 1, missing)
    add("skinet", "-o", ("rosbag", SYSTEM, "-o", "{tmp}/list.json"), 1,
        "{tmp}/list.json: error: already exists: a rosbag2 is written to a new folder")
    add("skinet", "-o", ("rosbag", SYSTEM, "--no-multicast-scouting", "--duration", "1", "-o", "{tmp}/no/such/bag"), 1,
        "{tmp}/no/such/bag: error: cannot write: No such file or directory")
    usage("skinet", "--storage", ("rosbag", SYSTEM, "-o", "{tmp}/bag", "--storage", "db3"),
          "argument --storage: invalid choice: 'db3' (choose from 'mcap', 'sqlite3')")
    usage("skinet", "--duration", ("rosbag", SYSTEM, "-o", "{tmp}/bag", "--duration", "0"),
          "argument --duration: " + seconds.format("0"))
    usage("skinet", "--namespace", ("rosbag", SYSTEM, "-o", "{tmp}/bag", "--namespace", "robot/*"),
          "argument --namespace: namespace 'robot/*' cannot be used in a Zenoh key "
          "(/-separated names of letters, digits, _ - .)")
    usage("skinet", "--domain", ("rosbag", SYSTEM, "-o", "{tmp}/bag", "--domain", "233"),
          "argument --domain: expected an integer from 0 to 232, got '233'")

    add("skinet", "system", ("run", "{tmp}/missing.toml"), 1, missing)
    add("skinet", "system", ("run", "{tmp}/badname.toml"), 1, bad_name)
    usage("skinet", "--duration", ("run", SYSTEM, "--duration", "-1"), "argument --duration: " + seconds.format("-1"))
    usage("skinet", "--outcome-timeout", ("run", SYSTEM, "--outcome-timeout", "0"),
          "argument --outcome-timeout: " + seconds.format("0"))
    usage("skinet", "--mode", ("run", SYSTEM, "--mode", "router"),
          "argument --mode/-m: invalid choice: 'router' (choose from 'peer', 'client')")
    usage("skinet", "--budget", ("run", SYSTEM, "--budget", "0"), "argument --budget: " + budget.format("0"))
    # Below the predictor's minimum the monitor would never ask, and every check would look fresh (issue 25).
    usage("skinet", "--budget", ("run", SYSTEM, "--budget", "0.01"), "argument --budget: " + budget.format("0.01"))
    usage("skinet", "--budget", ("run", SYSTEM, "--budget", "1e308"), "argument --budget: " + budget.format("1e308"))
    usage("skinet", "--memory-limit", ("run", SYSTEM, "--memory-limit", "tiny"),
          "argument --memory-limit: not a size: 'tiny' (e.g. 1GiB, 512MiB, 2GB)")

    usage("skinet", "--dashboard", ("run", SYSTEM, "--dashboard", "-1"),
          "argument --dashboard: expected an integer from 0 to 65535, got '-1'")
    add("skinet", "--dashboard-host", ("run", SYSTEM, "--once", "--no-multicast-scouting", "--dashboard", "0",
                                       "--dashboard-host", "999.0.0.1"), 1,
        "skinet: error: cannot listen on 999.0.0.1:0: Name or service not known")
    policy = ("argument --check-policy: unknown check policy 'lax' (presets: warn, strict; or KIND=ACTION with ACTION "
              "one of allow, warn, deny)")
    usage("skinet", "--check-policy", ("run", SYSTEM, "--check-policy", "lax"), policy)
    usage("skinet", "--rate-limit", ("run", SYSTEM, "--rate-limit", "-1"),
          "argument --rate-limit: expected a number >= 0, got '-1'")
    usage("skinet", "--check-rate-limit", ("run", SYSTEM, "--check-rate-limit", "fast"),
          "argument --check-rate-limit: expected a number >= 0, got 'fast'")
    usage("skinet", "--namespace", ("run", SYSTEM, "--namespace", "robot/*"),
          "argument --namespace: namespace 'robot/*' cannot be used in a Zenoh key "
          "(/-separated names of letters, digits, _ - .)")
    usage("skinet", "--domain", ("run", SYSTEM, "--domain", "233"),
          "argument --domain: expected an integer from 0 to 232, got '233'")
    usage("skinet", "--lost-after", ("run", SYSTEM, "--lost-after", "0.5"),
          "argument --lost-after: expected a number of seconds >= 1 (two heartbeat periods), got '0.5'")
    # the simulated robot of skinet run --simulate and python -m services.simulator SYSTEM --self-ending
    for program, base, flag in (("skinet", ("run", SYSTEM, "--simulate"), "--simulate"),
                                ("python -m services.simulator", (SYSTEM, "--self-ending"), "--self-ending")):
        usage(program, "--skill-duration", (*base, "--skill-duration", "-1"),
              "argument --skill-duration: expected a number of seconds >= 0, got '-1'")
        usage(program, "--skill-duration", (*base, "--skill-duration", "soon"),
              "argument --skill-duration: expected a number of seconds >= 0, got 'soon'")
        for bad in ("1.5", "-0.1", "nan"):
            usage(program, "--failure-rate", (*base, "--failure-rate", bad),
                  f"argument --failure-rate: expected a probability from 0 to 1, got '{bad}'")
        usage(program, "--seed", (*base, "--seed", "-1"), "argument --seed: expected an integer >= 0, got '-1'")
        usage(program, "--seed", (*base, "--seed", "x"), "argument --seed: expected an integer >= 0, got 'x'")
    add("skinet", "--failure-rate", ("run", SYSTEM, "--failure-rate", "0.5"), 1,
        "skinet: error: --failure-rate needs --simulate")
    add("skinet", "--simulate", ("run", "{tmp}/missing.toml", "--simulate"), 1, missing)
    usage("python -m services.simulator", "--seed", (SCENARIO, "--seed", "3"), "--seed needs --self-ending")
    usage("python -m services.simulator", "--self-ending", (SCENARIO, "--self-ending"),
          f"--self-ending takes a system file; {SCENARIO} is a scenario (its steps end the skills)")
    add("python -m services.simulator", "--self-ending", (SYSTEM,), 1,
        f"{SYSTEM}:4:1: error: a system file, not a scenario: add --self-ending to simulate its robot with skills "
        "that end by themselves")
    usage("skinet", "--format", ("record", "spot_arm", "-o", "{tmp}/rec.csv", "--format", "csv"),
          "argument --format: invalid choice: 'csv' (choose from 'jsonl', 'mcap')")

    # skinet watch, check, dashboard (operator views)
    for cmd, rest in (("watch", ()), ("check", ("spot:teleop.start",))):
        usage("skinet", "system", (cmd, "a/b", *rest),
              "argument SYSTEM_NAME: system name 'a/b' cannot be used in a Zenoh key (letters, digits, _ - . only)")
    usage("skinet", "--duration", ("watch", "spot_arm", "--duration", "0"), "argument --duration: " + seconds.format("0"))
    usage("skinet", "--wait", ("watch", "spot_arm", "--wait", "-1"), "argument --wait: " + seconds.format("-1"))
    add("skinet", "command", ("check", "spot_arm", "teleop"), 1,
        "skinet: error: command 'teleop' is not of the form skillset:transition (e.g. spot:teleop.start)")
    usage("skinet", "--timeout", ("check", "spot_arm", "x:y", "--timeout", "soon"),
          "argument --timeout: " + seconds.format("soon"))
    usage("skinet", "--wait", ("check", "spot_arm", "x:y", "--wait", "60"),
          "argument --wait: expected a number of seconds from 0 to 30, got '60'")
    add("skinet", "--policy", ("check", "spot_arm", "x:y", "--policy", "prediction_pending=allow"), 1,
        "skinet: error: check policy 'prediction_pending=allow': prediction_pending can only be warn or deny (the "
        "monitor never allows what it cannot vouch for)")
    add("skinet", "system", ("dashboard", "a/b"), 1,
        "skinet: error: system name 'a/b' cannot be used in a Zenoh key (letters, digits, _ - . only)")
    add("skinet", "system", ("dashboard", "{tmp}/missing.toml"), 1, missing)
    usage("skinet", "--port", ("dashboard", "spot_arm", "--port", "70000"),
          "argument --port/-p: expected an integer from 0 to 65535, got '70000'")
    usage("skinet", "--wait", ("dashboard", "spot_arm", "--wait", "-1"),
          "argument --wait: expected a number of seconds >= 0, got '-1'")
    add("skinet", "--host", ("dashboard", "spot_arm", "--no-multicast-scouting", "--port", "0", "--host", "999.0.0.1"),
        1, "skinet: error: cannot listen on 999.0.0.1:0: Name or service not known")
    usage("skinet", "--log-level", ("dashboard", "spot_arm", "--log-level", "LOUD"),
          "argument --log-level: expected one of DEBUG, INFO, WARNING, ERROR, CRITICAL, got 'LOUD'")
    usage("skinet", "--foxglove", ("dashboard", "spot_arm", "--foxglove", "70000"),
          "argument --foxglove: expected an integer from 0 to 65535, got '70000'")
    add("skinet", "system", ("foxglove", "a/b"), 1,
        "skinet: error: system name 'a/b' cannot be used in a Zenoh key (letters, digits, _ - . only)")
    add("skinet", "system", ("foxglove", "{tmp}/missing.toml"), 1, missing)
    usage("skinet", "--port", ("foxglove", "spot_arm", "--port", "70000"),
          "argument --port/-p: expected an integer from 0 to 65535, got '70000'")
    usage("skinet", "--wait", ("foxglove", "spot_arm", "--wait", "-1"),
          "argument --wait: expected a number of seconds >= 0, got '-1'")
    add("skinet", "--host", ("foxglove", "spot_arm", "--no-multicast-scouting", "--port", "0", "--host", "999.0.0.1"),
        1, "skinet: error: cannot serve Foxglove on 999.0.0.1:0: FoxgloveError: Failed to bind port: failed to lookup "
           "address information: Name or service not known")
    usage("skinet", "--log-level", ("foxglove", "spot_arm", "--log-level", "LOUD"),
          "argument --log-level: expected one of DEBUG, INFO, WARNING, ERROR, CRITICAL, got 'LOUD'")
    add("skinet", "--bundle", ("record", "spot_arm", "--no-multicast-scouting", "--duration", "1", "--bundle",
                               "{tmp}/no/such/b.mcap"), 1, "{tmp}/no/such/b.mcap: error: cannot write file: No such file "
                                                          "or directory")
    usage("skinet", "--foxglove", ("run", SYSTEM, "--foxglove", "-1"),
          "argument --foxglove: expected an integer from 0 to 65535, got '-1'")
    add("skinet", "--foxglove-host", ("run", SYSTEM, "--once", "--no-multicast-scouting", "--foxglove", "0",
                                      "--foxglove-host", "999.0.0.1"), 1,
        "skinet: error: --foxglove: cannot serve Foxglove on 999.0.0.1:0: FoxgloveError: Failed to bind port: failed to "
        "lookup address information: Name or service not known")
    for program, base, prefix in (("skinet", ("run", SYSTEM, "--once"), "skinet: error: "),
                                  ("python -m services.monitor", (SYSTEM,), "python -m services.monitor: error: ")):
        command = "skinet run" if program == "skinet" else program
        usage(program, "--incident-window", (*base, "--incident-window", "0"),
              "argument --incident-window: '0' is not a number of seconds from 0 (excluded) to 3600")
        add(program, "--incidents", (*base, "--no-multicast-scouting", "--incidents", "{tmp}/list.json"), 1,
            prefix + "--incidents {tmp}/list.json: cannot make the folder: File exists")
        usage(program, "--incidents-max-files", (*base, "--incidents-max-files", "0"),
              "argument --incidents-max-files: expected an integer >= 1, got '0'")
        usage(program, "--incidents-max-bytes", (*base, "--incidents-max-bytes", "-1GiB"),
              "argument --incidents-max-bytes: not a size: '-1GiB' (a size is positive, e.g. 1GiB, 512MiB, 2GB)")
    add("skinet", "--goal-user", ("dashboard", "spot_arm", "--port", "0", "--goal-user", "goalbox"), 1,
        "skinet: error: --goal-user goalbox logs in to a router: give its endpoint with --connect/-e")
    add("skinet", "--goal-secrets", ("dashboard", "spot_arm", "--port", "0", "--goal-user", "goalbox", "-e",
                                     "tcp/127.0.0.1:7447", "--goal-secrets", "{tmp}/none"), 1,
        "skinet: error: cannot read password file {tmp}/none/goalbox.password: No such file or directory")

    # skinet timeline
    add("skinet", "log", ("timeline", "{tmp}/missing.jsonl", "-o", "{tmp}/t.png"), 1,
        "{tmp}/missing.jsonl: error: cannot read file: No such file or directory")
    add("skinet", "log", ("timeline", "{tmp}/bad.jsonl", "-o", "{tmp}/t.png"), 1,
        "{tmp}/bad.jsonl:1: error: invalid JSON: Expecting value (column 1)")
    add("skinet", "-o", ("timeline", "{tmp}/run.jsonl", "-o", "{tmp}/t.xyz"), 1,
        "{tmp}/t.xyz: error: cannot write picture: Format 'xyz' is not supported (supported formats: avif, eps, "
        "gif, jpeg, jpg, pdf, pgf, png, ps, raw, rgba, svg, svgz, tif, tiff, webp)")
    add("skinet", "-o", ("timeline", "{tmp}/run.jsonl", "-o", "{tmp}/list.json/t.png"), 1,
        "{tmp}/list.json/t.png: error: cannot write picture: File exists")
    add("skinet", "--system", ("timeline", "{tmp}/run.jsonl", "-o", "{tmp}/t.png", "--system", "{tmp}/missing.toml"),
        1, missing)
    for bad in ("0", "5000", "high"):
        usage("skinet", "--dpi", ("timeline", "{tmp}/run.jsonl", "-o", "{tmp}/t.png", "--dpi", bad),
              f"argument --dpi: expected an integer from 10 to 1200, got '{bad}'")

    # skinet replay
    add("skinet", "log", ("replay", "{tmp}/missing.jsonl"), 1,
        "{tmp}/missing.jsonl: error: cannot read file: No such file or directory")
    add("skinet", "log", ("replay", "{tmp}/bad.jsonl"), 1,
        "{tmp}/bad.jsonl:1: error: invalid JSON: Expecting value (column 1)")
    add("skinet", "log", ("replay", "{tmp}/events.jsonl"), 1,
        "{tmp}/events.jsonl: error: no message of a monitor to replay (LiveState, Verdicts, UnsafeReport, "
        "StateSpaceReport, Divergences): the log holds 1 CanonicalEvent")
    live_options(("replay", "{tmp}/run.jsonl"))

    # the services' own options
    mon, pred, br, sim = (f"python -m services.{s}" for s in ("monitor", "predictor", "bridge_ros2", "simulator"))
    not_a_key = "cannot be used in a Zenoh key (letters, digits, _ - . only)"
    pilot = "python -m services.pilot"
    for program, base in ((mon, (SYSTEM,)), (br, (SYSTEM,)), (pilot, (SYSTEM,))):
        add(program, "system", ("{tmp}/missing.toml",), 1, missing)
        add(program, "system", ("{tmp}/badname.toml",), 1, bad_name)
    usage(pilot, "--instance", (SYSTEM, "--instance", "a/b"), f"argument --instance: instance id 'a/b' {not_a_key}")
    usage(pilot, "--budget", (SYSTEM, "--budget", "0.01"), "argument --budget: " + budget.format("0.01"))
    usage(pilot, "--budget", (SYSTEM, "--budget", "1e308"), "argument --budget: " + budget.format("1e308"))
    usage(pilot, "--response-timeout", (SYSTEM, "--response-timeout", "-1"),
          "argument --response-timeout: " + seconds.format("-1"))
    usage(pilot, "--outcome-timeout", (SYSTEM, "--outcome-timeout", "inf"),
          "argument --outcome-timeout: " + seconds.format("inf"))
    usage(pilot, "--memory-limit", (SYSTEM, "--memory-limit", "0MiB"),
          "argument --memory-limit: not a size: '0MiB' (e.g. 1GiB, 512MiB, 2GB)")
    usage(mon, "--id", (SYSTEM, "--id", "a b"), f"argument --id: instance id 'a b' {not_a_key}")
    usage(mon, "--budget", (SYSTEM, "--budget", "-1"), "argument --budget: " + budget.format("-1"))
    usage(mon, "--budget", (SYSTEM, "--budget", "0.049"), "argument --budget: " + budget.format("0.049"))
    usage(mon, "--budget", (SYSTEM, "--budget", "86401"), "argument --budget: " + budget.format("86401"))
    usage(mon, "--query-timeout", (SYSTEM, "--query-timeout", "0"), "argument --query-timeout: " + seconds.format("0"))
    usage(mon, "--query-timeout", (SYSTEM, "--budget", "2", "--query-timeout", "1.5"),
          "argument --query-timeout: 1.5 s is not above --budget 2 s: no prediction could ever arrive in time")
    usage(mon, "--stall", (SYSTEM, "--stall", "-2"), "argument --stall: " + seconds.format("-2"))
    usage(mon, "--check-policy", (SYSTEM, "--check-policy", "lax"), policy)
    usage(mon, "--check-rate-limit", (SYSTEM, "--check-rate-limit", "-3"),
          "argument --check-rate-limit: expected a number >= 0, got '-3'")
    usage(mon, "--check-rate-limit", (SYSTEM,), "argument --check-rate-limit: expected a number >= 0, got 'x' "
          "(from $SKINET_CHECK_RATE_LIMIT)", SKINET_CHECK_RATE_LIMIT="x")
    usage(mon, "--lost-after", (SYSTEM, "--lost-after", "nan"),
          "argument --lost-after: expected a number of seconds >= 1 (two heartbeat periods), got 'nan'")
    usage(mon, "--lost-after", (SYSTEM,), "argument --lost-after: expected a number of seconds >= 1 (two heartbeat "
          "periods), got '0' (from $SKINET_LOST_AFTER)", SKINET_LOST_AFTER="0")
    usage(pred, "--rate-limit", ("--rate-limit", "inf"), "argument --rate-limit: expected a number >= 0, got 'inf'")
    usage(pred, "--rate-burst", ("--rate-burst", "0"), "argument --rate-burst: expected a number >= 1, got '0'")
    usage(pred, "--instance", ("--instance", "a/b"), f"argument --instance: instance id 'a/b' {not_a_key}")
    usage(pred, "--instance", (), f"argument --instance: instance id 'a b' {not_a_key}", SKINET_INSTANCE="a b")
    for option in ("--workers", "--max-pending", "--cache"):
        usage(pred, option, (option, "0"), f"argument {option}: expected an integer >= 1, got '0'")
    usage(pred, "--fetch-timeout", ("--fetch-timeout", "-2"), "argument --fetch-timeout: " + seconds.format("-2"))
    usage(pred, "--max-budget", ("--max-budget", "0.01"), "argument --max-budget: " + budget.format("0.01"))
    usage(pred, "--max-budget", ("--max-budget", "1e308"), "argument --max-budget: " + budget.format("1e308"))
    usage(pred, "--memory-limit", ("--memory-limit", "1 GiBi"),
          "argument --memory-limit: not a size: '1 GiBi' (e.g. 1GiB, 512MiB, 2GB)")
    usage(pred, "--max-request", ("--max-request", "lots"),
          "argument --max-request: not a size: 'lots' (e.g. 1GiB, 512MiB, 2GB)")
    usage(pred, "--memory-mb", ("--memory-mb", "8"), "argument --memory-mb: expected an integer >= 64, got '8'")
    usage(pred, "--grace", ("--grace", "-2"), "argument --grace: " + seconds.format("-2"))
    usage(br, "--instance", (SYSTEM, "--instance", "*"), f"argument --instance: instance id '*' {not_a_key}")
    for program, base in ((br, (SYSTEM,)), (sim, (SCENARIO,)), (pilot, (SYSTEM,))):
        usage(program, "--namespace", (*base, "--namespace", "robot/*"),
              "argument --namespace: namespace 'robot/*' cannot be used in a Zenoh key "
              "(/-separated names of letters, digits, _ - .)")
        usage(program, "--domain", (*base, "--domain", "233"),
              "argument --domain: expected an integer from 0 to 232, got '233'")
        for level, env in (("--log-level", {}), ("", {"SKINET_LOG_LEVEL": "LOUD"})):
            argv = (*base, "--log-level", "LOUD") if level else base
            origin = " (from $SKINET_LOG_LEVEL)" if env else ""
            usage(program, "--log-level", argv, "argument --log-level: expected one of DEBUG, INFO, WARNING, ERROR, "
                  f"CRITICAL, got 'LOUD'{origin}", **env)
    for program, base in ((mon, (SYSTEM,)), (pred, ())):
        usage(program, "--log-level", (*base, "--log-level", "LOUD"),
              "argument --log-level: expected one of DEBUG, INFO, WARNING, ERROR, CRITICAL, got 'LOUD'")
    usage(br, "--status-poll", (SYSTEM, "--status-poll", "0"),
          "argument --status-poll: the status-request period must be 0.05 to 3600 s, got '0'")
    usage(br, "--silent-after", (SYSTEM, "--silent-after", "0"), "argument --silent-after: not a count from 1 to 1000: '0'")
    usage(br, "--domain", (SYSTEM,), "argument --domain: expected an integer from 0 to 232, got 'x' "
          "(from $ROS_DOMAIN_ID)", ROS_DOMAIN_ID="x")
    usage(br, "--namespace", (SYSTEM,), "argument --namespace: namespace 'a b' (from $SKINET_ROS_NAMESPACE) cannot "
          "be used in a Zenoh key (/-separated names of letters, digits, _ - .)", SKINET_ROS_NAMESPACE="a b")
    usage(br, "--hold", (SYSTEM, "--hold", "-1"), "argument --hold: expected a number of seconds >= 0, got '-1'")
    usage(br, "--settle", (SYSTEM, "--settle", "soon"), "argument --settle: expected a number of seconds >= 0, "
                                                          "got 'soon'")
    add("skinet", "system", ("conform", "{tmp}/missing.toml", "{tmp}/run.mcap"), 1, missing)
    add("skinet", "bags", ("conform", SYSTEM, "{tmp}/missing.db3"), 1,
        "{tmp}/missing.db3: error: cannot read file: No such file or directory")
    add(br, "--replay", (SYSTEM, "--replay", "{tmp}/missing.db3"), 1,
        "{tmp}/missing.db3: error: cannot read file: No such file or directory")
    add(br, "--replay", (SYSTEM, "--no-multicast-scouting", "--replay", SPOT), 1,
        f"{SPOT}: error: cannot replay: Unrecognized storage format '.rl'")
    add(br, "--replay", (SYSTEM, "--no-multicast-scouting", "--replay", "{tmp}/run.jsonl"), 1,
        "{tmp}/run.jsonl: error: a SkiNet monitor log (JSON Lines, skinet record), not a rosbag2 file of the "
        "managers: replay it with 'skinet replay {tmp}/run.jsonl'")
    add(sim, "scenario", ("{tmp}/missing.toml",), 1, missing)
    add(sim, "scenario", ("{tmp}/unknown_skillset.toml",), 1,
        "{tmp}/unknown_skillset.toml:6:1: error: step 1: unknown skillset 'spott' (skillsets of spot_arm: spot, manipulator)")
    usage(sim, "--dds", (SCENARIO, "--dds", "--rmw-zenoh"), "--dds and --rmw-zenoh exclude each other")
    usage(sim, "--speed", (SCENARIO, "--speed", "-1"), "argument --speed: expected a number >= 0, got '-1'")
    usage(sim, "--speed", (SCENARIO,), "argument --speed: expected a number >= 0, got 'fast' (from $SKINET_SPEED)",
          SKINET_SPEED="fast")
    usage(sim, "--start-delay", (SCENARIO, "--start-delay", "-1"),
          "argument --start-delay: expected a number of seconds >= 0, got '-1'")
    usage(sim, "--linger", (SCENARIO, "--linger", "later"),
          "argument --linger: expected a number of seconds >= 0, got 'later'")
    # skinet router --robots, skinet fleet
    add("skinet", "--robots", ("router", "--no-auth", "--robots", "tcp/robot2:7447"), 1,
        "skinet: error: robot endpoint 'tcp/robot2:7447' must be tls/HOST:PORT (a robot's router accepts TLS only)")
    add("skinet", "--handed", ("router", "--no-auth", "--secrets", "{tmp}/own", "--handed", "{tmp}/no/such/dir"), 1,
        "skinet: error: handed-out secrets folder {tmp}/no/such/dir does not exist")
    add("skinet", "host", ("fleet", "--secrets", "{tmp}/fleet", "add", "bad host/x"), 1,
        "skinet: error: robot name 'bad host/x' must be the host of its endpoint (letters, digits, '.', '-')")
    # skinet client-config
    add("skinet", "--secrets", ("client-config", "--secrets", "{tmp}/no/such/dir"), 1,
        "skinet: error: secrets folder {tmp}/no/such/dir does not exist")
    usage("skinet", "--user", ("client-config", "--user", "bad/name"),
          "argument --user: user name 'bad/name' cannot be used in a Zenoh key (letters, digits, _ - . only)")
    add("skinet", "--connect", ("client-config", "--connect", "tcp/127.0.0.1:7447"), 1,
        "skinet: error: --connect 'tcp/127.0.0.1:7447': the router checks certificates on a tls/ endpoint only, "
        "e.g. tls/127.0.0.1:7447")
    add("skinet", "-o", ("client-config", "-o", "{tmp}/observer.txt"), 1,
        "skinet: error: {tmp}/observer.txt: the name must end with .json5 or .json (Zenoh reads the format from it)")
    return cases


CASES = _cases()


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bad (and a few good) input files the cases name with {tmp}."""
    tmp = tmp_path_factory.mktemp("errors")
    skillsets = ROOT / "skillsets"
    (tmp / "badname.toml").write_text(
        f'[system]\nname = "has space/slash"\nproperties = "{skillsets / "spot_arm.props"}"\n'
        f'[[skillsets]]\nmodel = "{skillsets / "spot.rl"}"\n[[skillsets]]\nmodel = "{skillsets / "manipulator.rl"}"\n')
    (tmp / "list.json").write_text("[]")
    (tmp / "bad.json5").write_text('{\n  mood: "peer",\n}\n')
    (tmp / "syntax.json5").write_text("{mode\n")
    (tmp / "bad.jsonl").write_text("not json\n")
    head = f'[scenario]\nname = "bad"\nsystem = "{SYSTEM}"\n[[steps]]\n'
    (tmp / "unknown_skillset.toml").write_text(head + 't = 1.0\nskillset = "spott"\ntransition = "init_power.start"\n')
    (tmp / "unknown_transition.toml").write_text(head + 't = 1.0\nskillset = "spot"\ntransition = "init_power.strat"\n')
    (tmp / "bad_time.toml").write_text(head + 't = "soon"\nskillset = "spot"\ntransition = "init_power.start"\n')
    (tmp / "impossible.json").write_text('{"spot": {"running": ["stand_up"]}}')
    goals = {
        "empty": "# nothing\n",
        "syntax": "[[goals]]\nreach = \"spot:Busy\"\nrun\n",
        "top_key": "goal = 3\n",
        "goal_key": '[[goals]]\nreach = "spot:Busy"\n\n[[goals]]\nreach = "spot:Idle"\ninput = {}\n',
        "both": '[[goals]]\nreach = "spot:Busy"\nrun = "spot:teleop"\n',
        "neither": "[[goals]]\ninputs = {}\n",
        "formula": '[[goals]]\nreach = "spot:Busy"\n\n[[goals]]\nreach = "spot:Standing and spot:Bussy"\n',
        "not_string": "[[goals]]\nreach = 3\n",
        "input_type": '[[goals]]\nrun = "spot:go_to_waypoint"\ninputs = { go_to_waypoint = { target = "home" } }\n',
        "input_field": '[[goals]]\nrun = "spot:go_to_waypoint"\ninputs = { go_to_waypoint = { target = { x = 1.0, '
                       'y = "north" } } }\n',
        "input_name": '[[goals]]\nrun = "spot:go_to_waypoint"\ninputs = { go_to_waypoint = { goal = 1 } }\n',
        "input_skill": '[[goals]]\nrun = "spot:go_to_waypoint"\ninputs = { go_to_waypont = { target = {} } }\n',
        "input_missing": '[[goals]]\nrun = "spot:go_to_waypoint"\n',
    }
    for name, text in goals.items():
        (tmp / f"goals_{name}.toml").write_text(text)
    assert skinet_main.main(["demo", "--core", "--no-predict", "--log", str(tmp), SCENARIO]) == 0
    (tmp / "unassisted.jsonl").rename(tmp / "run.jsonl")
    event = next(line for line in (tmp / "run.jsonl").read_text().splitlines() if '"CanonicalEvent"' in line)
    (tmp / "events.jsonl").write_text(event + "\n")  # a log with no monitor message
    return tmp


@pytest.fixture(scope="module")
def busy_port() -> Iterator[int]:
    """A port of 127.0.0.1 with a listener on it."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


@pytest.fixture
def keep_signal_handlers() -> Iterator[None]:
    """Services install SIGINT/SIGTERM handlers; a failed start must not leave them to pytest."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


def _fill(text: str, tmp: Path, port: int) -> str:
    return text.replace("{tmp}", str(tmp)).replace("{port}", str(port))


@pytest.mark.parametrize("case", CASES, ids=str)
def test_bad_value_gives_one_line_and_exit_status(case: Case, files: Path, busy_port: int,
                                                  capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
                                                  keep_signal_handlers: None) -> None:
    for name in ("SKINET_ZENOH_MODE", "SKINET_ZENOH_CONNECT", "SKINET_ZENOH_LISTEN", "SKINET_ZENOH_CONFIG",
                 "SKINET_INSTANCE", "SKINET_LOG_LEVEL", "SKINET_SPEED", "ROS_DOMAIN_ID", "SKINET_ROS_NAMESPACE"):
        monkeypatch.delenv(name, raising=False)
    for name, value in case.env:
        monkeypatch.setenv(name, _fill(value, files, busy_port))
    main = PROGRAMS[case.program][0]
    try:
        code = main([_fill(a, files, busy_port) for a in case.argv])
    except SystemExit as exc:  # the argument parser
        code = exc.code
    out, err = capsys.readouterr()
    assert (code, err) == (case.code, _fill(case.error, files, busy_port) + "\n")
    assert out == ""


def _options(parser: argparse.ArgumentParser, flags: bool = False) -> Iterator[tuple[str, str]]:
    """(command, option) for every option taking a value (and every flag too with ``flags``)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from ((f"{parser.prog} {name}", o) for _, o in _options(sub, flags))
        elif (flags or action.nargs != 0) and not isinstance(action, argparse._HelpAction):
            yield parser.prog, (action.option_strings[0] if action.option_strings else action.dest)


def test_every_option_has_a_bad_value_case() -> None:
    options = {o for _, factory in PROGRAMS.values() for o in _options(factory())}
    everything = {o for _, factory in PROGRAMS.values() for o in _options(factory(), flags=True)}
    covered = {(c.command, c.option) for c in CASES} | set(FREE_TEXT)
    assert sorted(options - covered) == []
    assert sorted(covered - everything) == []  # no case names an option that does not exist


# As real processes: what a user sees, from the entry points themselves.
PROCESS_CASES = [
    (["-m", "skinet_cli.main", "run", SYSTEM, "--listen", "garbage"], 1,
     "skinet: error: --listen 'garbage': an endpoint is PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447"),
    (["-m", "services.monitor", SYSTEM, "--listen", "garbage"], 1,
     "python -m services.monitor: error: --listen 'garbage': an endpoint is PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447"),
    (["-m", "services.predictor", "--workers", "0"], 2,
     "python -m services.predictor: error: argument --workers: expected an integer >= 1, got '0' "
     "(see python -m services.predictor --help)"),
    (["-m", "services.bridge_ros2", SYSTEM, "--connect", "tcp/1.2.3.4:99999"], 1,
     "python -m services.bridge_ros2: error: --connect 'tcp/1.2.3.4:99999': port '99999' is not a number from 0 "
     "to 65535"),
    (["-m", "services.simulator", SCENARIO, "--zenoh-config", "/no/such/zenoh.json5"], 1,
     "/no/such/zenoh.json5: error: cannot read file: No such file or directory"),
    (["-m", "services.foxglove", SYSTEM, "--feed", "0"], 2,  # standard input, not a pipe (subprocess.run's default)
     "python -m services.foxglove: error: argument --feed: expected the number of a pipe open in this process, got "
     "'0' (see python -m services.foxglove --help)"),
    (["-m", "services.dashboard", SYSTEM, "--port", "70000"], 2,
     "python -m services.dashboard: error: argument --port/-p: expected an integer from 0 to 65535, got '70000' (see "
     "python -m services.dashboard --help)"),
]


@pytest.mark.parametrize(("argv", "code", "error"), PROCESS_CASES, ids=[" ".join(c[0][1:3]) for c in PROCESS_CASES])
def test_entry_point_processes(argv: list[str], code: int, error: str) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SKINET_")}
    r = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=60, cwd=ROOT, env=env)
    assert (r.returncode, r.stderr, r.stdout) == (code, error + "\n", "")


def test_an_unexpected_exception_is_one_line(capsys: pytest.CaptureFixture[str],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(args: argparse.Namespace) -> int:
        raise RuntimeError("boom")

    monkeypatch.setattr(skinet_main, "cmd_parse", broken)
    monkeypatch.delenv("SKINET_TRACEBACK", raising=False)
    code = skinet_main.main(["parse", SPOT])
    assert (code, capsys.readouterr().err) == (70, "skinet: internal error: RuntimeError: boom (a bug: please report "
                                                   "it; SKINET_TRACEBACK=1 shows the traceback)\n")
    monkeypatch.setenv("SKINET_TRACEBACK", "1")
    with pytest.raises(RuntimeError, match="boom"):
        skinet_main.main(["parse", SPOT])



def test_any_title_is_drawn(files: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A title with "$" (matplotlib's mathtext) is drawn as written, not parsed."""
    code = skinet_main.main(["timeline", str(files / "run.jsonl"), "-o", str(files / "t.png"), "--title", "$\\frac{$"])
    assert (code, capsys.readouterr().err) == (0, "")


def test_missing_corpus_skips_only_the_tests_that_read_it_in_one_line(tmp_path: Path) -> None:
    """Without ../shared beside the repository, the tests that read the corpus are skipped, summed up in one line,
    and the others run (issue 32, item 1)."""
    tests = tmp_path / "repo" / "tests"
    tests.mkdir(parents=True)
    for name in ("conftest.py", "corpus.py"):
        (tests / name).write_text((ROOT / "tests" / name).read_text())
    (tests / "test_some.py").write_text(
        "import pytest\nfrom corpus import require_corpus\n\n"
        "def test_nothing():\n    pass\n\n"
        "def test_fixture(corpus_dir):\n    assert False\n\n"
        "def test_helper():\n    require_corpus()\n    assert False\n\n"
        "@pytest.mark.corpus\ndef test_marked():\n    assert False\n")
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-ra", "-p", "no:cacheprovider", "-p", "no:xdist", str(tests)],
                       capture_output=True, text=True, timeout=120, cwd=tests.parent)
    assert r.returncode == 0, r.stdout + r.stderr
    skipped = [line for line in r.stdout.splitlines() if line.startswith("SKIPPED")]
    assert skipped == ["SKIPPED [3] tests/conftest.py: needs the third-party test corpus ../shared/corpus "
                       f"({tmp_path / 'shared' / 'corpus'}), absent here: put the project's shared/ folder beside the "
                       "repository to run these (CI has it)"], r.stdout
    assert r.stdout.splitlines()[-1].startswith("1 passed, 3 skipped in ")


def test_ctrl_c_while_the_arguments_are_read_is_an_interruption_not_a_traceback(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C inside Python 3.11's ``parse_known_intermixed_args`` while it formats the usage, before it saved the
    positionals' ``nargs``, broke its clean-up with an AttributeError over the KeyboardInterrupt: ``skinet goal``
    printed that traceback and exited 1 (a full run's test_goal.py, once)."""
    def interrupted(self: argparse.ArgumentParser) -> str:
        raise KeyboardInterrupt

    monkeypatch.setattr(argparse.ArgumentParser, "format_usage", interrupted)
    assert skinet_main.main(["goal", "spot_arm", "reach spot:Standing"]) == 130
    assert capsys.readouterr().err == "skinet: interrupted\n"
