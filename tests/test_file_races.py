"""Files read on request are opened once and checked on what was opened (issue 31, item 2).

A loader that checks a resolved name and then opens the unresolved one can be
raced: a link swapped in between reads a file outside the model's folder, and a
FIFO swapped in blocks the loader for ever.  These tests load a model in a bounded
loop while another thread swaps the included file (or a folder on its path) for
a link out of the folder or for a FIFO, and count escapes and hangs.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from skinet.errors import SourceError
from skinet.files.read import FileRefused, read_bytes
from skinet.system.load import load_model

LOADS = 1500
HANG = 60.0  # seconds for all the loads; a load blocked on a FIFO never ends


def _swapping(swap: Callable[[int], None], stop: threading.Event) -> threading.Thread:
    def run() -> None:
        i = 0
        while not stop.is_set():
            swap(i)
            i += 1
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def _race(model: Path, swap: Callable[[int], None], fifos: list[Path]) -> tuple[int, int, int]:
    """(escapes, refusals, loads that finished) of LOADS loads of ``model`` while ``swap`` runs."""
    outcome = {"escapes": 0, "refused": 0, "done": 0}

    def loads() -> None:
        for _ in range(LOADS):
            try:
                names = [s.name for s in load_model(model).skillsets]
                outcome["escapes"] += "leaked" in names
            except SourceError:
                outcome["refused"] += 1
            outcome["done"] += 1

    stop = threading.Event()
    swapper = _swapping(swap, stop)
    loader = threading.Thread(target=loads, daemon=True)
    loader.start()
    loader.join(HANG)
    hung, finished = loader.is_alive(), outcome["done"]
    stop.set()
    swapper.join(10)
    if hung:  # release the loader blocked in open(): a writer on the FIFO
        for fifo in fifos:
            try:
                os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:
                pass
        loader.join(10)
    assert not hung, f"a load blocked: {finished} of {LOADS} loads had finished, escapes {outcome['escapes']}"
    return outcome["escapes"], outcome["refused"], outcome["done"]


@pytest.fixture
def folders(tmp_path: Path) -> tuple[Path, Path]:
    """``models/`` with ``m.rl`` including ``x.rl``; ``outside/x.rl`` holds skillset ``leaked``."""
    models, outside = tmp_path / "models", tmp_path / "outside"
    models.mkdir()
    outside.mkdir()
    (outside / "x.rl").write_text("skillset leaked {}\n")
    return models, outside


def test_a_link_or_fifo_swapped_in_for_an_included_file(folders: tuple[Path, Path]) -> None:
    models, outside = folders
    model = models / "m.rl"
    model.write_text('include "x.rl"\nskillset main {}\n')
    (models / "real.rl").write_text("skillset inside {}\n")
    target, fifo = models / "x.rl", models / "fifo"
    os.link(models / "real.rl", target)
    os.mkfifo(fifo)  # one FIFO, linked in each time: a writer on it releases a reader blocked on it

    def swap(i: int) -> None:  # each rename is atomic: x.rl is always one of the three
        if i % 2:
            os.link(models / "real.rl", models / "tmp")
        elif i % 4 == 0:
            os.symlink(outside / "x.rl", models / "tmp")
        else:
            os.link(fifo, models / "tmp")
        os.replace(models / "tmp", target)

    escapes, refused, done = _race(model, swap, [fifo])
    assert (escapes, done) == (0, LOADS)
    assert 0 < refused < LOADS  # both outcomes were met: the race ran


def test_a_folder_swapped_for_a_link_on_the_included_path(folders: tuple[Path, Path]) -> None:
    """O_NOFOLLOW guards the last name only: the descriptor's own path is checked too."""
    models, outside = folders
    model = models / "m.rl"
    model.write_text('include "lib/x.rl"\nskillset main {}\n')
    (models / "real").mkdir()
    (models / "real" / "x.rl").write_text("skillset inside {}\n")
    (models / "away").symlink_to(outside)
    lib = models / "lib"
    (models / "real").rename(lib)

    def swap(i: int) -> None:  # lib is the real folder or a link to outside/ (or briefly missing)
        if i % 2 == 0:
            lib.rename(models / "real")
            (models / "away").rename(lib)
        else:
            lib.rename(models / "away")
            (models / "real").rename(lib)

    escapes, refused, done = _race(model, swap, [])
    assert (escapes, done) == (0, LOADS)
    assert 0 < refused < LOADS


def test_read_bytes_refuses_what_it_opened(tmp_path: Path) -> None:
    """The checks, one by one, with their exact reasons."""
    root = tmp_path / "root"
    root.mkdir()
    (root / "ok.txt").write_text("ok\n")
    (tmp_path / "secret.txt").write_text("s3cr3t\n")
    (root / "out").symlink_to(tmp_path / "secret.txt")
    os.mkfifo(root / "pipe")
    (root / "big").write_bytes(b"x" * 11)
    assert read_bytes(root / "ok.txt", 10, root)[0] == b"ok\n"
    for name, reason in [("out", f"it lies outside {root}"), ("pipe", "not a regular file"),
                         ("big", "file too large: 11 bytes (the limit is 10)"),
                         (".", "cannot read file: Is a directory"),
                         ("none", "cannot read file: No such file or directory")]:
        with pytest.raises(FileRefused) as info:
            read_bytes(root / name, 10, root)
        assert info.value.reason == reason, name
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with pytest.raises(FileRefused) as info:
        read_bytes(tmp_path / "loop")
    assert info.value.reason == "cannot read file: Too many levels of symbolic links"


def test_a_definition_file_linked_out_of_its_folder_is_refused(tmp_path: Path) -> None:
    """A binding's message definitions stay in its definitions folder, like includes."""
    from skinet.system.load import _read_definitions

    folder = tmp_path / "interfaces"
    (folder / "pkg" / "msg").mkdir(parents=True)
    (tmp_path / "Secret.msg").write_text("string s3cr3t\n")
    (folder / "pkg" / "msg" / "Leak.msg").symlink_to(tmp_path / "Secret.msg")
    with pytest.raises(SourceError) as info:
        _read_definitions(folder, "b.binding.toml")
    assert str(info.value) == f"{folder / 'pkg/msg/Leak.msg'}: error: it lies outside {folder}"
