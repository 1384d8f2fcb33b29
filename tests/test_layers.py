"""The layers of the tree (README, Layout; issue 25): the core imports neither its shells nor
the command line, and the simulator's modules depend on each other one way only."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


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


def test_the_core_imports_neither_services_nor_the_command_line() -> None:
    assert offenders("skinet", ("services", "skinet_cli")) == []


def test_the_layer_check_sees_a_lazy_import(tmp_path: Path) -> None:
    (tmp_path / "skinet" / "verify").mkdir(parents=True)
    (tmp_path / "skinet" / "verify" / "probe.py").write_text(
        "def f():\n    from services.chain import run_chain\n    from ..cli import x\n    return run_chain, x\n")
    assert offenders("skinet", ("services", "skinet.cli"), tmp_path) == [
        "skinet/verify/probe.py imports services.chain", "skinet/verify/probe.py imports services.chain.run_chain",
        "skinet/verify/probe.py imports skinet.cli", "skinet/verify/probe.py imports skinet.cli.x"]


def test_the_simulator_driver_does_not_import_its_service() -> None:
    assert [name for name in imports(ROOT / "services/simulator/driver.py")
            if name.startswith("services.simulator.service")] == []
