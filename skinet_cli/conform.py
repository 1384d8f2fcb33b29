"""``skinet conform SYSTEM BAG...``: replay recorded bags against the model, offline (docs/semantics.md §9 *Conformance*).

Each bag (rosbag2, sqlite3 or mcap) is replayed from the model's initial marking
through the bridge's own derivation (managers' statuses, and the bindings of bound
skillsets) and the monitor's live marking.  Every model divergence is reported with
its time in the bag and what the model expected; the command exits 3 if any was
found (0 otherwise, 1 on bad input).  Results of goals are not in bags: modes
come from the bindings' defaults, and the report says how often that happened.
"""

from __future__ import annotations

import argparse
import json
import logging
from datetime import datetime, timezone
from collections.abc import Mapping
from pathlib import Path

from skinet.errors import SkinetError, SourceError
from skinet.system.load import load_bindings, load_typemap
from skinet.system.live import LiveSystem
from skinet.ros.binding import Binding
from skinet.system.model import System
from skinet.wire.messages import CanonicalEvent
from services.common.options import load_live_system, print_warnings

DIVERGENCE_EXIT = 3


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser("conform", help="replay rosbag2 files against the model and report every divergence",
                       description="Replay rosbag2 files (sqlite3 or mcap) through the bridge's derivation and the "
                                   "live nets, from the model's initial marking, and report every model divergence "
                                   "with its time and what the model expected. Exit status: 0 none, 3 some, 1 bad "
                                   "input.")
    c.add_argument("system", help="system file (.toml); bound skillsets name their binding file")
    c.add_argument("bags", nargs="+", metavar="BAG", help="rosbag2 file or folder, each replayed on its own")
    c.add_argument("--json", action="store_true", help="machine-readable report")
    c.set_defaults(func=cmd_conform)


def cmd_conform(args: argparse.Namespace) -> int:
    system, warnings = load_live_system(args.system)
    bindings, more = load_bindings(system)
    print_warnings([*warnings, *more])
    typemap = load_typemap(args.system)
    for bag in args.bags:  # every bag named must exist before the first replay
        if not Path(bag).exists():
            raise SourceError.at(bag, None, "cannot read file: No such file or directory")
    logger = logging.getLogger("skinet.bridge_ros2")
    was, logger.disabled = logger.disabled, True  # the report below says it all, once
    try:
        reports = [_conform(bag, system, typemap, bindings) for bag in args.bags]
    finally:
        logger.disabled = was
    if args.json:
        print(json.dumps(reports, indent=2))
    else:
        for r in reports:
            print(_text(r))
    return DIVERGENCE_EXIT if any(r["divergences"] for r in reports) else 0


def _conform(bag: str, system: System, typemap: Mapping[str, str], bindings: Mapping[str, Binding]) -> dict:
    """The report of one bag: replayed from the model's initial marking, its divergences in time order."""
    from services.bridge_ros2.bound import replay_bags  # rosbags' reader only when the command runs

    live = LiveSystem(system)
    found: list[tuple[float, str, str]] = []
    events = [0]

    def apply(ev: CanonicalEvent) -> None:
        events[0] += 1
        out = live.apply(ev.skillset, ev.transition, ev.status.model_dump() if ev.status else None)
        # A bound skillset's drifts come with the message that showed them (below); the live nets
        # only add what the derivation did not see.
        if out.divergence and not ev.divergence:
            what = f"{ev.transition or 'status'}: {out.divergence}" + (f" ({ev.info})" if ev.info else "")
            found.append((ev.stamp, ev.skillset, what))

    try:
        done = replay_bags(bag, system, typemap, bindings, apply, source="skinet conform")
    except SkinetError:
        raise
    except Exception as exc:  # rosbags reader errors: not a bag, unknown storage
        raise SourceError.at(bag, None, f"cannot replay: {exc}") from None
    feed = done.bound
    if feed is not None:
        found += [(d.stamp, d.skillset, str(d)) for d in feed.drifts]
    found.sort(key=lambda f: f[0])
    counters = feed.counters if feed is not None else None
    messages = (counters.messages if counters else 0) + (done.managers.counters.messages if done.managers else 0)
    return {
        "bag": bag, "messages": messages, "events": events[0], "start": done.start,
        "divergences": [{"stamp": s, "offset": s - (done.start or s), "skillset": k, "what": w}
                        for s, k, w in found],
        "unrecorded": done.unrecorded,
        "bad_input": dict(counters.bad) if counters else {},
        "malformed": (counters.malformed if counters else 0)
                     + (done.managers.counters.malformed if done.managers else 0),
    }


# What a count means where its name alone does not say it (the bridge logs the details, quiet here).
_WHY = {
    "result not recorded": "goals that ended with no result in the bag (a rosbag records topics, and action "
                           "results are services): their mode is the binding's default",
}


def _text(r: dict) -> str:
    n = len(r["divergences"])
    lines = [f"{r['bag']}: {r['messages']} messages, {r['events']} events, "
             f"{n} model divergence{'s' if n != 1 else ''}"]
    for d in r["divergences"]:
        when = datetime.fromtimestamp(d["stamp"], timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
        lines.append(f"  +{d['offset']:.3f} s ({when}) {d['skillset']}: {d['what']}")
    for topic in r["unrecorded"]:
        lines.append(f"  not recorded: {topic}")
    if r["malformed"]:
        lines.append(f"  malformed messages dropped: {r['malformed']}")
    for kind, count in sorted(r["bad_input"].items()):
        why = _WHY.get(kind)
        lines.append(f"  {kind}: {count}" + (f" ({why})" if why else ""))
    return "\n".join(lines)


__all__ = ["add_parser", "cmd_conform"]
