"""``skinet timeline``: draw a monitor log as an operator timeline (paper Fig. 3 / Fig. 4).

matplotlib is imported only when a picture is drawn (Agg canvas, no display).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from services.common.options import count, load_live_system, print_warnings
from skinet.errors import SkinetError, SourceError
from skinet.files.read import read_text
from skinet.system.model import System
from skinet.wire.log import Entry, read_log
from skinet.wire.mcap_log import MAGIC, is_mcap, read_mcap, rosbag_refused
from skinet.wire.messages import LiveState

SQLITE = b"SQLite format 3\x00"  # a rosbag2 in its sqlite3 storage


def add_parser(sub: argparse._SubParsersAction) -> None:
    c = sub.add_parser("timeline", help="draw a monitor log (skinet record, skinet demo --log) as a timeline picture")
    c.add_argument("log", metavar="LOG.jsonl|LOG.mcap", help="monitor log, JSON Lines or MCAP (skinet record)")
    c.add_argument("-o", "--output", required=True, metavar="timeline.png",
                   help="picture to write (format from the extension: png, svg, pdf)")
    c.add_argument("--title", help="title (default: system and log name)")
    c.add_argument("--system", help="system file (.toml) giving the lanes when the log has no model bundle")
    c.add_argument("--dpi", type=count(10, 1200), default=100, help="resolution of raster pictures (default: 100)")
    c.set_defaults(func=cmd_timeline)


def save_timeline(entries: Sequence[Entry], title: str, output: str | Path, system: System | None = None,
                  dpi: int = 100) -> Path:
    """Draw ``entries`` and write the picture; raises :class:`SourceError` when it cannot be written."""
    from skinet.plot.timeline import draw  # matplotlib is slow to import

    figure = draw(entries, title, system)
    path = Path(output)
    try:
        if path.parent != Path(""):
            path.parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(path, dpi=dpi)
    except (OSError, ValueError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else " ".join(str(exc).split())
        raise SourceError.at(str(path), None, f"cannot write picture: {reason}") from None
    return path


def load_log(path: str) -> list[Entry]:
    """A monitor log in either format (MCAP is recognised by its magic bytes); a rosbag2 (its folder, or
    its SQLite file) is refused in one line that points to ``skinet conform``."""
    if os.path.isfile(os.path.join(path, "metadata.yaml")):
        raise SourceError.at(path, None, rosbag_refused())
    try:
        with open(path, "rb") as f:
            if f.read(len(SQLITE)) == SQLITE:
                raise SourceError.at(path, None, rosbag_refused())
            f.seek(0)
            if is_mcap(f.read(len(MAGIC))):
                f.seek(0)
                return read_mcap(f, path, lambda text: print(text, file=sys.stderr))
    except OSError as exc:
        raise SourceError.at(path, None, f"cannot read file: {exc.strerror}") from None
    return read_log(read_text(path).splitlines(), path)


def cmd_timeline(args: argparse.Namespace) -> int:
    entries = load_log(args.log)
    system = None
    if args.system:
        system, warnings = load_live_system(args.system)
        print_warnings(warnings)
    # "$" would start matplotlib's mathtext (and a syntax error there): titles are shown as written.
    title = args.title.replace("$", r"\$") if args.title is not None else _default_title(entries, args.log)
    try:
        path = save_timeline(entries, title, args.output, system, args.dpi)
    except SkinetError as exc:
        if isinstance(exc, SourceError):
            raise
        raise SourceError.at(args.log, None, str(exc)) from None
    print(f"timeline of {len(entries)} messages written to {path}")
    return 0


def _default_title(entries: Sequence[Entry], log: str) -> str:
    names = sorted({e.message.system for e in entries if isinstance(e.message, LiveState)})
    return f"{', '.join(names) or 'unknown system'}: {Path(log).stem}"
