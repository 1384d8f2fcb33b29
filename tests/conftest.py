"""Shared fixtures: the real-world corpus and the paper's system (docs/how-it-works.md).

The corpus (real skillset files and ROS 2 message definitions written by others)
lives in ``shared/corpus`` beside the repository root; it is read in place, never
copied into the project.  A clone with nothing beside it still runs every other
test: the tests that read the corpus are marked ``corpus`` (explicitly, by using
the ``corpus_dir`` or ``corpus_skillset`` fixtures, or by a module-level path to
the corpus in a module that marks none of its tests) and are skipped there, in one
line of the summary that gives their number.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from skinet.lang.model import Skillset
from skinet.lang.parser import parse_skillset
from skinet.system.model import System, build_system

from corpus import CORPUS, CORPUS_ABSENT, REPO

CORPUS_FILES = ("spot.rl", "manipulator.rl", "isae_robot/isae_robot.rl")
SKILLSETS = REPO / "skillsets"
PAPER_FILES = ("spot.rl", "manipulator.rl")
PAPER_MANAGERS = {"spot": "/spot/spot_skillset_manager", "manipulator": "/kinova/manipulator_skillset_manager"}


CORPUS_FIXTURES = frozenset({"corpus_dir", "corpus_skillset"})


def pytest_configure(config: pytest.Config) -> None:
    # A test run started in the background of a non-interactive shell (``make test &``, a CI runner's script)
    # inherits SIGINT ignored, and so do the commands it starts: Python keeps an ignored SIGINT ignored, so a test's
    # Ctrl-C (SIGINT sent to a command) would be lost until the command installs its own handler (a fresh
    # machine's run saw ``skinet goal`` go on after one).  The tests play an operator's terminal: Ctrl-C acts.
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    config.addinivalue_line("markers", "corpus: reads the third-party test corpus ../shared/corpus (skipped, in one "
                                       "summary line, where it is absent)")


def needs_corpus(item: pytest.Item) -> bool:
    """Whether ``item`` reads the corpus: marked ``corpus``, using a corpus fixture, or in a module that
    holds a path to the corpus and marks none of its tests (a new module that forgot the mark)."""
    if item.get_closest_marker("corpus") is not None or CORPUS_FIXTURES & set(getattr(item, "fixturenames", ())):
        return True
    module = getattr(item, "module", None)
    if module is None or getattr(module, "_corpus_marks", False):
        return False
    return any(isinstance(v, Path) and _inside_corpus(v) for v in vars(module).values())


def _inside_corpus(path: Path) -> bool:
    path = Path(os.path.normpath(path))
    return path == CORPUS or CORPUS in path.parents


def _skip_without_corpus(items: list[pytest.Item]) -> None:
    if CORPUS.is_dir():
        return
    marked = {id(i.module) for i in items if getattr(i, "module", None) is not None
              and i.get_closest_marker("corpus") is not None}
    for item in items:
        module = getattr(item, "module", None)
        if module is not None and id(module) in marked:
            module._corpus_marks = True  # explicit marks there: no module-wide guess
    for item in items:
        if needs_corpus(item):
            item.add_marker(pytest.mark.skip(reason=CORPUS_ABSENT))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    """Every test skipped for the corpus is reported at one place, so ``-ra`` sums them up in one line."""
    outcome = yield
    report = outcome.get_result()
    if report.skipped and isinstance(report.longrepr, tuple) and CORPUS_ABSENT in str(report.longrepr[2]):
        report.longrepr = (str(Path(__file__)), None, f"Skipped: {CORPUS_ABSENT}")


def _shares_module_state(item: pytest.Item) -> bool:
    """Whether ``item`` uses a fixture kept across tests of its module (a deployment, a stack, a router)."""
    info = getattr(item, "_fixtureinfo", None)
    return info is not None and any(d.scope in ("class", "module", "package")
                                    for defs in info.name2fixturedefs.values() for d in defs)


# Modules that time the services under load run one after the other on one worker: the rate-limit
# test's flood saturates both cores of a 2-core machine, and beside it the container mission (steps
# 0.2 s apart) saw verdicts come 1.7 s late.
SHARED_GROUPS = {"tests/deploy/test_containers.py": "timed", "tests/deploy/test_rate_limit.py": "timed"}


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under ``--dist loadgroup`` (``make test``) some modules run whole on one worker, in file order.

    These are the slow modules and those whose tests share a module-scoped fixture: such a fixture
    (a compose stack, a fleet, a deployment the tests move on step by step) is then set up once and
    its tests see it in the order they were written; the modules of ``SHARED_GROUPS`` share one
    group.  The Docker images and the cargo target are built once, behind ``docker/build.sh``'s lock
    and cargo's own.  Every other test is handed out alone.
    """
    _skip_without_corpus(items)
    for item in items:
        if item.get_closest_marker("slow") is not None or _shares_module_state(item):
            module = item.nodeid.split("::")[0]
            item.add_marker(pytest.mark.xdist_group(SHARED_GROUPS.get(module, module)))


def load_corpus_skillset(name: str) -> Skillset:
    """Parse one corpus file (``name`` relative to the corpus folder)."""
    return parse_skillset((CORPUS / name).read_text(encoding="utf-8"), name)


def load_paper_skillset(name: str) -> Skillset:
    """Parse one of the paper's skillsets from ``skillsets/``."""
    return parse_skillset((SKILLSETS / name).read_text(encoding="utf-8"), name)


def load_paper_system() -> System:
    """The paper's system: spot + manipulator with ``spot_arm.props``."""
    skillsets = [load_paper_skillset(f) for f in PAPER_FILES]
    props = (SKILLSETS / "spot_arm.props").read_text(encoding="utf-8")
    return build_system(
        "spot_arm", [(ss, PAPER_MANAGERS[ss.name]) for ss in skillsets], props, "spot_arm.props"
    )


@pytest.fixture(scope="session")
def corpus_dir() -> Path:
    """``shared/corpus`` beside the repository root (tests using it are skipped where it is absent)."""
    return CORPUS


@pytest.fixture(scope="session")
def corpus_skillset():
    """Loader of corpus skillsets: ``corpus_skillset("spot.rl")``."""
    return load_corpus_skillset


@pytest.fixture(scope="session")
def paper_skillset():
    """Loader of the paper's skillsets: ``paper_skillset("spot.rl")``."""
    return load_paper_skillset


@pytest.fixture(scope="session")
def paper_system() -> System:
    """The paper's system, built once per session (systems are immutable)."""
    return load_paper_system()
