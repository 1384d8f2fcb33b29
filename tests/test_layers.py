"""The floors of the house (docs/how-it-works.md, "The house"; issue 33).

``skinet`` (the core) <- ``services`` (each deployable service, and ``services/common``) <- ``chains``
(the services tied together in one process) <- ``skinet_cli`` (argument parsing and printing) <-
``benchmarks``.  No import runs up a floor, lazy ones included, no two modules import each other through
any path, ``services/`` holds only service folders, and the core's top level only its face and the
modules everything uses."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

ROOT = Path(__file__).resolve().parents[1]
FLOORS = ("skinet", "services", "chains", "skinet_cli", "benchmarks")
SERVICES = ("bridge_ros2", "dashboard", "foxglove", "monitor", "pilot", "predictor", "secrets", "simulator")
CORE_TOP = {"__init__.py", "errors.py", "closenames.py"}


def imports(path: Path, root: Path = ROOT) -> set[str]:
    """Every module ``path`` imports, at top level or inside a function (relative imports resolved)."""
    package = ".".join(path.relative_to(root).with_suffix("").parts[:-1])
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def offenders(folder: str, forbidden: tuple[str, ...], root: Path = ROOT) -> list[str]:
    return sorted(f"{path.relative_to(root)} imports {name}"
                  for path in (root / folder).rglob("*.py")
                  for name in imports(path, root)
                  if any(name == f or name.startswith(f + ".") for f in forbidden))


def module_graph(root: Path = ROOT) -> nx.DiGraph:
    """Modules of every floor and the project modules each imports (a package stands for its ``__init__``)."""
    modules: dict[str, Path] = {}
    for floor in FLOORS:
        for path in (root / floor).rglob("*.py"):
            name = ".".join(path.relative_to(root).with_suffix("").parts)
            modules[name.removesuffix(".__init__")] = path
    graph = nx.DiGraph()
    for name, path in modules.items():
        graph.add_node(name)
        for imported in imports(path, root):
            while imported and imported not in modules:  # a name imported from a module: the module
                imported = imported.rpartition(".")[0]
            if imported and imported != name:
                graph.add_edge(name, imported)
    return graph


def test_no_floor_imports_a_floor_above_it() -> None:
    for i, floor in enumerate(FLOORS):
        assert offenders(floor, FLOORS[i + 1:]) == [], floor


def test_no_modules_import_each_other() -> None:
    assert sorted(sorted(c) for c in nx.simple_cycles(module_graph())) == []


def test_the_checks_see_a_lazy_import_and_a_circle(tmp_path: Path) -> None:
    for floor in FLOORS:
        (tmp_path / floor).mkdir()
    (tmp_path / "skinet" / "verify").mkdir()
    (tmp_path / "skinet" / "verify" / "probe.py").write_text(
        "def f():\n    from chains.chain import run_chain\n    from ..cli import x\n    return run_chain, x\n")
    assert offenders("skinet", ("chains", "skinet.cli"), tmp_path) == [
        "skinet/verify/probe.py imports chains.chain", "skinet/verify/probe.py imports chains.chain.run_chain",
        "skinet/verify/probe.py imports skinet.cli", "skinet/verify/probe.py imports skinet.cli.x"]
    (tmp_path / "services" / "a.py").write_text("def f():\n    from services.b import g\n")
    (tmp_path / "services" / "b.py").write_text("from services import a\n")
    assert [sorted(c) for c in nx.simple_cycles(module_graph(tmp_path))] == [["services.a", "services.b"]]


def test_services_holds_only_deployable_services_and_what_they_share() -> None:
    folders = sorted(p.name for p in (ROOT / "services").iterdir() if p.is_dir() and p.name != "__pycache__")
    loose = sorted(p.name for p in (ROOT / "services").glob("*.py"))
    assert (folders, loose) == (sorted([*SERVICES, "common"]), ["__init__.py"])
    assert [s for s in SERVICES if not (ROOT / "services" / s / "__main__.py").is_file()] == []


def test_the_core_top_level_is_its_face_and_what_everything_uses() -> None:
    assert {p.name for p in (ROOT / "skinet").glob("*.py")} == CORE_TOP


def test_the_simulator_driver_does_not_import_its_service() -> None:
    assert [name for name in imports(ROOT / "services/simulator/driver.py")
            if name.startswith("services.simulator.service")] == []
