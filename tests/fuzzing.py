"""Mutation fuzzer of every input SkiNet reads: ``.rl`` models, properties, CTL
formulas, JSON state files and TOML system files.

Each mutated input goes through the parser and the core of the commands that
read it (``skinet parse`` and ``net`` for a model, ``unsafe`` for a system,
``ctl`` for a formula, ``--state`` loading for a state).  The only acceptable
failure is a :class:`~skinet.errors.SkinetError` (a clear one-line error); any
other exception is *uncaught*, and an input that takes longer than the timeout
is a *hang*.

``tests/test_fuzz.py`` runs it under hypothesis, bounded in examples; run it at
scale from the repository root::

    .venv/bin/python tests/fuzzing.py --count 10000 [--seed 1] [--timeout 10]

It prints per kind the inputs tried, refused with a clear error, accepted,
uncaught and hung, with the slowest input and the peak memory.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import random
import re
import resource
import signal
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script
    sys.path.insert(0, str(REPO))

from skinet_cli.main import main as skinet_main  # noqa: E402
from skinet.errors import SkinetError  # noqa: E402
from skinet.system.load import load_state, load_system
from skinet.lang.larkerrors import MAX_FORMULA_CHARS, MAX_SOURCE_CHARS  # noqa: E402
from skinet.lang.parser import parse_model  # noqa: E402
from skinet.net.build import build_net  # noqa: E402
from skinet.net.export import FORMATS  # noqa: E402
from skinet.props.parser import parse_formula, parse_properties  # noqa: E402
from skinet.system.model import System, marking_problems  # noqa: E402
from skinet.verify.algorithm1 import analyse  # noqa: E402
from skinet.verify.ctl import Kripke, check  # noqa: E402
from skinet.verify.explore import explore  # noqa: E402

SKILLSETS = REPO / "skillsets"
CORPUS = REPO.parent / "shared" / "corpus"
KINDS = ("rl", "props", "formula", "state", "system")

# Tokens worth inserting: keywords and operators of both grammars, the bodies that
# used to crash (deep nesting, unterminated comments), and odd characters.
TOKENS = (
    "skillset", "type", "data", "resource", "event", "skill", "state", "initial", "transition", "all",
    "guard", "effect", "input", "output", "parameter", "precondition", "start", "invariant", "progress",
    "period", "1 sec", "100 ms", "1.0", "message", "interrupt", "interrupting", "true", "false",
    "postcondition", "p:", "success", "failure", "not", "and", "or", "=>", "==", "!=", "->", "(", ")",
    "{", "}", "<", ">", ",", ":", ".", "=", "#", "\n", " ", "/*", "*/", "//", "\"", "'", "\\", "\t",
    "[", "]", "E[", "A(", " U ", "AG", "EF", "AX", "spot:Busy", "manipulator:HP", "spot:i_teleop",
    "r == A", "x", "é", "\u0000", "\ufeff", "9" * 30, "-1", "1e999", "null", "[]", "{}",
    "not " * 120, "(" * 600, ")" * 600, "a == b and " * 150, "true or " * 150, "AG " * 150,
    "/*" + "x" * 200, "[" * 2000, "{a=" * 400, "running", "resources", "\\u0000", "../", "/dev/zero",
    'include "spot.rl"', 'include "nowhere.rl"',
)


def texts(kind: str) -> list[str]:
    """The real files each kind of input is mutated from."""
    return [p.read_text(encoding="utf-8") for p in _bases(kind)]


@cache
def _bases(kind: str) -> tuple[Path, ...]:
    if kind == "rl":
        found = [SKILLSETS / "spot.rl", SKILLSETS / "manipulator.rl"]
        found += [p for p in (CORPUS / "spot.rl", CORPUS / "manipulator.rl", CORPUS / "isae_robot" / "isae_robot.rl")
                  if p.exists()]
        return tuple(found)
    if kind == "props":
        return (SKILLSETS / "spot_arm.props",)
    if kind == "system":
        return (SKILLSETS / "spot_arm.toml",)
    return ()


FORMULAS = (
    "AG not (spot:Busy and manipulator:Busy)",
    "EF (spot:i_go_to_waypoint and not manipulator:HP)",
    "A[spot:Idle U spot:Busy]",
    "E(spot:PowerOff U (spot:PowerOn and AX true))",
    "AG (spot:i_teleop => EF spot:e_teleop)",
)
STATES = (
    {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Busy"},
              "running": ["teleop"]}},
    {"spot": {"resources": {"power_status": "PowerOn", "posture": "Standing"}},
     "manipulator": {"resources": {"arm_status": "RD"}}},
    {"manipulator": {"running": ["arm_ready"], "resources": {"mutex": "Busy", "arm_status": "Moving"}}},
)


def mutate(text: str, rng: random.Random, rounds: int | None = None) -> str:
    """``text`` after 1 to 8 random edits, usually one (delete, duplicate, insert, replace, swap, truncate)."""
    for _ in range(rounds if rounds is not None else rng.choice((1, 1, 1, 2, 3, 8))):
        n = len(text)
        i = rng.randint(0, n)
        j = min(n, i + rng.choice((1, 2, 5, 20, 200)))
        op = rng.randrange(9)
        if op >= 7:  # keeps the syntax: one name of the text replaced by another
            names = list(re.finditer(r"[A-Za-z_][A-Za-z0-9_]*", text))
            if names:
                old, new = rng.choice(names), rng.choice(names)
                text = text[:old.start()] + new.group() + text[old.end():]
        elif op == 0:
            text = text[:i] + text[j:]
        elif op == 1:
            text = text[:j] + text[i:j] * rng.choice((1, 2, 50)) + text[j:]
        elif op in (2, 3):
            text = text[:i] + rng.choice(TOKENS) + text[i:]
        elif op == 4:
            text = text[:i] + rng.choice(TOKENS) + text[j:]
        elif op == 5:
            lines = text.split("\n")
            a, b = rng.randrange(len(lines)), rng.randrange(len(lines))
            lines[a], lines[b] = lines[b], lines[a]
            text = "\n".join(lines)
        else:
            text = text[:i]
    return text


def mutate_json(value: object, rng: random.Random) -> object:
    """A structural mutation of a JSON value: a node replaced by an odd value."""
    odd = ([], {}, None, 3, -1.5, True, "", "teleop", ["teleop"], {"x": []}, [[["deep"]]], "Standing")
    if isinstance(value, dict) and value and rng.random() < 0.7:
        key = rng.choice(list(value))
        out = dict(value)
        if rng.random() < 0.2:
            out[rng.choice(("resources", "running", "spot", "zzz", ""))] = rng.choice(odd)
        else:
            out[key] = mutate_json(value[key], rng)
        return out
    if isinstance(value, list) and value and rng.random() < 0.7:
        out_list = list(value)
        k = rng.randrange(len(out_list))
        out_list[k] = mutate_json(out_list[k], rng)
        return out_list
    return rng.choice(odd)


# ---- what each kind of input goes through ------------------------------------------------


@cache
def paper() -> tuple[System, Kripke]:
    """The paper's system and its explored state space (for formulas)."""
    system, _ = load_system(SKILLSETS / "spot_arm.toml")
    return system, Kripke(explore(system, system.initial_marking(), budget=10.0))


def run_rl(text: str, workdir: Path) -> None:
    model = parse_model(text, "fuzz.rl")
    for ss in model.skillsets:
        for eventless in (False, True):
            net = build_net(ss, eventless=eventless)
            for export in FORMATS.values():
                export(net)
    path = workdir / "fuzz.rl"
    path.write_text(text, encoding="utf-8")
    _cli("parse", str(path), "--json")
    # An accepted model is also explored, as a system of its own, under a budget.
    (workdir / "fuzz.toml").write_text('[system]\nname = "fuzz"\n[[skillsets]]\nmodel = "fuzz.rl"\n')
    _cli("explore", str(workdir / "fuzz.toml"), "--budget", "1", "--json")


def run_props(text: str, workdir: Path) -> None:
    system, _ = paper()
    parse_properties(text, {c.name: c.skillset for c in system.components}, "fuzz.props")
    _copy_system(workdir, props=text)
    _cli("unsafe", str(workdir / "spot_arm.toml"), "--no-predict", "--json")


def run_formula(text: str, workdir: Path) -> None:
    system, kripke = paper()
    formula = parse_formula(text, {c.name: c.skillset for c in system.components})
    check(kripke, formula)


def run_state(text: str, workdir: Path) -> None:
    system, _ = paper()
    path = workdir / "state.json"
    path.write_text(text, encoding="utf-8")
    for what_if in (False, True):
        try:
            marking = load_state(path, system, what_if)
        except SkinetError:
            if what_if:
                raise
            continue
        marking_problems(system, marking)
        analyse(system, marking, None)


def run_system(text: str, workdir: Path) -> None:
    _copy_system(workdir, toml=text)
    system, _ = load_system(workdir / "spot_arm.toml")
    analyse(system, system.initial_marking(), None)


RUNNERS: dict[str, Callable[[str, Path], None]] = {
    "rl": run_rl, "props": run_props, "formula": run_formula, "state": run_state, "system": run_system,
}


def _copy_system(workdir: Path, toml: str | None = None, props: str | None = None) -> None:
    for name in ("spot.rl", "manipulator.rl", "spot_arm.types.json"):
        target = workdir / name
        if not target.exists():
            target.write_text((SKILLSETS / name).read_text(encoding="utf-8"), encoding="utf-8")
    (workdir / "spot_arm.toml").write_text(toml if toml is not None else (SKILLSETS / "spot_arm.toml").read_text(), encoding="utf-8")
    (workdir / "spot_arm.props").write_text(props if props is not None else (SKILLSETS / "spot_arm.props").read_text(), encoding="utf-8")


def _cli(*argv: str) -> None:
    """Run a command in-process; a clear error exits 1, anything else escapes."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = skinet_main(list(argv))
    if code not in (0, 1):
        raise AssertionError(f"skinet {' '.join(argv)} exited {code}")


def generate(kind: str, rng: random.Random) -> str:
    """One mutated input of ``kind``."""
    if kind == "formula":
        return mutate(rng.choice(FORMULAS), rng)
    if kind == "state":
        if rng.random() < 0.5:
            return json.dumps(mutate_json(rng.choice(STATES), rng))
        return mutate(json.dumps(rng.choice(STATES)), rng)
    return mutate(rng.choice(texts(kind)), rng)


# ---- the campaign --------------------------------------------------------------------------


class Hang(Exception):
    pass


@dataclass
class Tally:
    tried: int = 0
    refused: int = 0
    accepted: int = 0
    uncaught: list[str] = field(default_factory=list)
    hangs: list[str] = field(default_factory=list)
    slowest: float = 0.0


def run_one(kind: str, text: str, workdir: Path) -> str | None:
    """``None`` when the input was accepted or refused cleanly, else the traceback."""
    try:
        RUNNERS[kind](text, workdir)
    except SkinetError:
        return None
    except Hang:
        raise
    except Exception:  # noqa: BLE001 - the point is to catch everything else
        return traceback.format_exc()
    return None


def campaign(
    count: int, seed: int, timeout: float, out: Path | None = None, progress: bool = False
) -> dict[str, Tally]:
    rng = random.Random(seed)
    tallies = {k: Tally() for k in KINDS}
    paper()  # explored once, outside the timed inputs

    def alarm(signum: int, frame: object) -> None:
        raise Hang()

    signal.signal(signal.SIGALRM, alarm)
    with tempfile.TemporaryDirectory(prefix="skinet-fuzz-") as tmp:
        workdir = Path(tmp)
        for n in range(count):
            if progress and n and n % 1000 == 0:
                print(f"  {n} inputs...", file=sys.stderr, flush=True)
            kind = KINDS[n % len(KINDS)]
            text = generate(kind, rng)
            tally = tallies[kind]
            tally.tried += 1
            t0 = time.perf_counter()
            signal.setitimer(signal.ITIMER_REAL, timeout)
            try:
                failure = run_one(kind, text, workdir)
                refused = failure is None and _refused(kind, text, workdir)
            except Hang:
                tally.hangs.append(text)
                failure, refused = None, False
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            tally.slowest = max(tally.slowest, time.perf_counter() - t0)
            if failure is not None:
                tally.uncaught.append(failure)
                if out is not None:
                    (out / f"uncaught-{kind}-{n}.txt").write_text(text)
            elif refused:
                tally.refused += 1
            else:
                tally.accepted += 1
    return tallies


def _refused(kind: str, text: str, workdir: Path) -> bool:
    """Whether the parser refused ``text`` (cheap: parsing only)."""
    try:
        if kind == "rl":
            parse_model(text, "fuzz.rl")
        elif kind == "formula":
            system, _ = paper()
            parse_formula(text, {c.name: c.skillset for c in system.components})
        elif kind == "props":
            system, _ = paper()
            parse_properties(text, {c.name: c.skillset for c in system.components})
        elif kind == "state":
            load_state(workdir / "state.json", paper()[0])
        else:
            load_system(workdir / "spot_arm.toml")
    except SkinetError:
        return True
    return False


BIG = 10 * 2**20  # 10 MiB


def big_inputs(workdir: Path) -> list[str]:
    """The largest accepted inputs, and 10 MiB inputs of each kind as files and texts:
    time and peak memory (tracemalloc)."""
    import tracemalloc

    system, _ = paper()
    skillsets = {c.name: c.skillset for c in system.components}
    event = "event e%d { guard (r == A or r != B) and not r == B effect r -> A }\n"
    events = "".join(event % i for i in range((MAX_SOURCE_CHARS - 100) // len(event % 99999)))
    bodies: dict[str, tuple[str, Callable[[str], object]]] = {
        "rl at the size limit": ("skillset s { resource r { state { A B } initial A transition all }\n" + events + "}",
                                 lambda t: parse_model(t)),
        "formula at its limit": ("(" * MAX_FORMULA_CHARS, lambda t: parse_formula(t, skillsets)),
        "rl, unterminated /*": ("skillset s { /*" + "x" * BIG, lambda t: parse_model(t)),
        "rl, 'not' x 2.6 M": ("skillset s { event e { guard " + "not " * (BIG // 4), lambda t: parse_model(t)),
        "property": ("p = " + "(" * BIG, lambda t: parse_properties(t, skillsets)),
        "formula": ("AG " * (BIG // 3), lambda t: parse_formula(t, skillsets)),
        "state file": ("[" * BIG, lambda t: load_state(_write(workdir / "big.json", t), system)),
        "system file": ("a = " + "[" * BIG, lambda t: load_system(_write(workdir / "big.toml", t))),
    }
    rows = []
    for name, (text, parse) in bodies.items():
        tracemalloc.start()
        t0 = time.perf_counter()
        try:
            parse(text)
            outcome = "parsed"
        except SkinetError as exc:
            outcome = str(exc).split(": error: ")[-1][:60]
        elapsed = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        rows.append(f"  {name:22} {len(text) / 2**20:5.1f} MiB  {elapsed:6.2f} s  peak {peak / 2**20:6.1f} MiB"
                    f" ({peak / len(text):4.1f} x)  {outcome}")
    return rows


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def report(tallies: dict[str, Tally], elapsed: float) -> str:
    rows = [f"{'kind':8} {'tried':>7} {'refused':>8} {'accepted':>9} {'uncaught':>9} {'hangs':>6} {'slowest':>9}"]
    total = Tally()
    for kind, t in tallies.items():
        rows.append(f"{kind:8} {t.tried:7} {t.refused:8} {t.accepted:9} {len(t.uncaught):9} {len(t.hangs):6} {t.slowest:8.2f}s")
        total.tried += t.tried
        total.refused += t.refused
        total.accepted += t.accepted
        total.uncaught += t.uncaught
        total.hangs += t.hangs
        total.slowest = max(total.slowest, t.slowest)
    rows.append(f"{'total':8} {total.tried:7} {total.refused:8} {total.accepted:9} {len(total.uncaught):9} "
                f"{len(total.hangs):6} {total.slowest:8.2f}s")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    rows.append(f"{total.tried} inputs in {elapsed:.0f} s, peak memory {peak:.0f} MB")
    return "\n".join(rows)


def cli(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--count", type=int, default=10_000, help="inputs to try, spread over the kinds (default: 10000)")
    p.add_argument("--seed", type=int, default=1, help="random seed (default: 1)")
    p.add_argument("--timeout", type=float, default=10.0, help="seconds after which an input counts as a hang")
    p.add_argument("--keep", type=Path, help="write each input that failed to this folder")
    args = p.parse_args(argv)
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    tallies = campaign(args.count, args.seed, args.timeout, args.keep, progress=True)
    print(report(tallies, time.perf_counter() - t0))
    print("Big inputs (peak traced memory beyond the input itself; budget for 10 MiB: 20 x):")
    with tempfile.TemporaryDirectory(prefix="skinet-fuzz-") as tmp:
        print("\n".join(big_inputs(Path(tmp))))
    for t in tallies.values():
        for failure in t.uncaught[:3]:
            print(failure, file=sys.stderr)
    return 1 if any(t.uncaught or t.hangs for t in tallies.values()) else 0


def examples(kind: str, rng: random.Random) -> Iterator[str]:  # pragma: no cover - helper for exploring
    while True:
        yield generate(kind, rng)


if __name__ == "__main__":
    sys.exit(cli())
