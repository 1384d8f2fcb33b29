"""How a printed hint calls ``skinet`` (or ``python``) again, so that it works when pasted.

A clone's ``make`` targets install ``skinet`` in ``.venv/bin``, which is not on ``PATH`` until the
shell activates it (README, "Calling skinet").  A command started as ``.venv/bin/skinet`` therefore
names ``.venv/bin/skinet`` (and ``.venv/bin/python`` for ``python -m services...``) in the lines it
prints; a ``skinet`` that ``PATH`` finds, an in-process call and ``python -m skinet_cli.main`` (the
tests' and developers' way) name plain ``skinet`` and ``python``.  This is the core's file layer
because it looks at the file system: one ``PATH`` search per process (cached).
"""

from __future__ import annotations

import functools
import os
import shutil
import sys
from pathlib import Path

NAME = "skinet"


@functools.cache
def skinet() -> str:
    """``skinet``, or the path the running ``skinet`` script was started by when ``PATH`` finds another
    ``skinet`` or none."""
    started = sys.argv[0] if sys.argv else ""
    if Path(started).name != NAME:
        return NAME
    found = shutil.which(NAME)
    if found and os.path.abspath(found) == os.path.abspath(started):
        return NAME
    return started


def python() -> str:
    """``python``, or the interpreter beside the ``skinet`` script of :func:`skinet` when that is a path."""
    name = skinet()
    if name == NAME:
        return "python"
    beside = Path(name).with_name("python")
    return str(beside) if beside.exists() else sys.executable
