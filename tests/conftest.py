"""Shared fixtures: the real-world corpus and the paper's system (SPEC §2-§5).

The corpus lives in ``shared/corpus`` beside the repository root; it is read in
place, never copied into the project.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from skinet.lang.model import Skillset
from skinet.lang.parser import parse_skillset
from skinet.system import System, build_system

REPO = Path(__file__).resolve().parents[1]
CORPUS = REPO.parent / "shared" / "corpus"
CORPUS_FILES = ("spot.rl", "manipulator.rl", "isae_robot/isae_robot.rl")
SKILLSETS = REPO / "skillsets"
PAPER_FILES = ("spot.rl", "manipulator.rl")
PAPER_MANAGERS = {"spot": "/spot/spot_skillset_manager", "manipulator": "/kinova/manipulator_skillset_manager"}


def pytest_configure(config: pytest.Config) -> None:
    """Stop at once, with one line saying what is missing, when the corpus is not beside the repository."""
    if not CORPUS.is_dir():
        raise pytest.UsageError(
            f"the test corpus is missing: {CORPUS} does not exist. The tests read real skillset files and "
            f"ROS 2 message definitions from ../shared/corpus beside the repository ({REPO}); put the "
            "project's shared/ folder there (it is never copied into the project)")


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
    """``shared/corpus`` beside the repository root."""
    assert CORPUS.is_dir(), f"corpus folder missing: {CORPUS}"
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
