"""Build hook: a wheel ships the demo's files, copied at build time from the checkout's ``skillsets/``
and ``examples/nav2/`` into ``skinet_cli/demo_files/``, so that an installed ``skinet demo`` runs from
any folder (docs/commands.md, "Every command"; :func:`skinet_cli.demo.demo_roots` finds them).  An editable
install copies nothing: it reads the checkout's folders.  Cost: one copy of about 250 kB per build."""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
SHIPPED = (Path("skillsets"), Path("examples") / "nav2")  # what skinet demo reads, under its own names


class BuildWithDemoFiles(build_py):
    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        target = Path(self.build_lib) / "skinet_cli" / "demo_files"
        for folder in SHIPPED:
            shutil.copytree(HERE / folder, target / folder, dirs_exist_ok=True,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))


setup(cmdclass={"build_py": BuildWithDemoFiles})
