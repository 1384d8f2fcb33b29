"""``skinet net --format promela``: Spin finds exactly our stable markings (docs/semantics.md §3, §6.1)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from skinet_cli.main import main
from skinet.system.load import load_system
from skinet.net.export.promela import to_promela
from skinet.net.union import union
from skinet.verify.explore import explore
from tests.corpus import require_corpus

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT.parent / "shared" / "corpus"


def corpus_pair_file(folder: Path) -> Path:
    if not CORPUS.exists():
        require_corpus()
    (folder / "pair.toml").write_text(
        f'[system]\nname = "pair"\nproperties = "{CORPUS / "spot_manipulator.props"}"\n'
        f'[[skillsets]]\nmodel = "{CORPUS / "spot.rl"}"\n[[skillsets]]\nmodel = "{CORPUS / "manipulator.rl"}"\n'
    )
    return folder / "pair.toml"


def spin_states(model: Path) -> int:
    """Spin's "states, stored" for ``model`` (exhaustive search, deadlocks allowed)."""
    work = model.parent
    subprocess.run(["spin", "-a", model.name], cwd=work, check=True, capture_output=True, timeout=300)
    # -O0: pan.c of a skillset union is large and gcc -O2 takes minutes on it.
    subprocess.run(["gcc", "-O0", "-DNOCLAIM", "-DSAFETY", "-o", "pan", "pan.c"], cwd=work, check=True,
                   capture_output=True, timeout=900)
    # -m is the DFS stack depth, allocated up front: 10^8 cost 5 GB of page faults for a depth of a few hundred.
    out = subprocess.run(["./pan", "-E", "-m1000000"], cwd=work, check=True, capture_output=True, text=True,
                         timeout=300).stdout
    assert "errors: 0" in out, out
    return int(re.search(r"(\d+) states, stored", out).group(1))


def test_model_shape(tmp_path: Path) -> None:
    system, _ = load_system(ROOT / "skillsets" / "spot_arm.toml")
    text = to_promela(union([c.eventless for c in system.components], system.name))
    assert text.count("bit p") == sum(len(c.eventless.places) for c in system.components)
    invariants = sum(1 for c in system.components for t in c.eventless.transitions if t.kind == "invariant")
    steps = sum(1 for c in system.components for t in c.eventless.transitions if t.kind != "invariant")
    assert text.count("        :: en") == steps and text.count("\n    :: en") == invariants
    assert text.count("cascade()") == 2  # defined once, called once
    assert "!(en" not in text  # invariants first: steps start at stable markings, no guard needed
    assert main(["net", str(ROOT / "skillsets" / "spot_arm.toml"), "--eventless", "--format", "promela",
                 "-o", str(tmp_path / "m.pml")]) == 0
    assert (tmp_path / "m.pml").read_text() == text


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("spin") is None or shutil.which("gcc") is None, reason="spin or gcc not installed")
@pytest.mark.parametrize("which", ["paper", "corpus pair"])
def test_spin_stores_our_stable_markings(which: str, tmp_path: Path) -> None:
    path = ROOT / "skillsets" / "spot_arm.toml" if which == "paper" else corpus_pair_file(tmp_path)
    assert main(["net", str(path), "--eventless", "--format", "promela", "-o", str(tmp_path / "m.pml")]) == 0
    system, _ = load_system(path)
    ours = explore(system, event_seeds=False, memory_limit=None).markings
    assert ours == {"paper": 63, "corpus pair": 496}[which]
    assert spin_states(tmp_path / "m.pml") == ours
