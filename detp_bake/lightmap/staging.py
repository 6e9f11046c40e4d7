"""A set of output files that appear together or not at all.

Each file is first written under a hidden temporary name next to its target (same folder, so the
final rename is atomic on every platform); `commit` renames them all at the end. Any exception
before that (a cancel, a full disk, a bug) removes every temporary file, including one that was
being written when it failed, so a bake never leaves a `.…partial…` file or a 0-byte image behind,
and files already in the folder are only ever replaced by complete ones.
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Callable

try:
    import fcntl
except ImportError:  # Windows: no advisory locks on a folder
    fcntl = None


class FileSet:
    """Use as a context manager: on leaving it by an exception, the staged files are removed."""

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self.staged: list[tuple[Path, Path]] = []  # (temporary, target)

    def stage(self, name: str, write: Callable[[Path], None]) -> Path:
        """Call `write(temporary path)` for the file `name` in the folder; returns the target."""
        target = self.folder / name
        base, dot, ext = name.rpartition(".")
        tmp = self.folder / (f".{base}.{os.getpid()}.partial.{ext}" if dot else f".{name}.{os.getpid()}.partial")
        self.staged.append((tmp, target))  # before writing: a write that fails half-way is removed too
        try:
            write(tmp)
        except OSError as exc:  # name the file it was for, not the temporary one
            raise OSError(exc.errno, exc.strerror or str(exc), str(target)) from None
        return target

    def stage_text(self, name: str, text: str) -> Path:
        return self.stage(name, lambda tmp: tmp.write_text(text, encoding="utf-8"))

    def commit(self) -> None:
        """Rename every staged file onto its target; what is left unrenamed on an error is removed.
        One set at a time per folder (a lock on the folder itself): two bakes into one folder at
        once leave all of one bake's files, the later one's, never some of each."""
        with _folder_lock(self.folder):
            while self.staged:
                tmp, target = self.staged[0]
                os.replace(tmp, target)
                self.staged.pop(0)

    def discard(self) -> None:
        for tmp, _ in self.staged:
            try:
                tmp.unlink()
            except OSError:
                pass  # never created, or already gone
        self.staged.clear()

    def __enter__(self) -> "FileSet":
        return self

    def __exit__(self, kind, value, tb) -> bool:
        if kind is not None:
            self.discard()
        return False


@contextlib.contextmanager
def _folder_lock(folder: Path):
    """An exclusive advisory lock (flock) on the folder, held while the block runs; nothing where
    the system has none (Windows). The lock goes with the process: a killed bake holds none."""
    if fcntl is None:
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing the last descriptor releases the lock
