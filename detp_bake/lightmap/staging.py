"""A set of output files that appear together or not at all.

Each file is first written under a hidden temporary name next to its target (same folder, so the
final rename is atomic on every platform); `commit` renames them all at the end. Any exception
before that (a cancel, a full disk, a bug) removes every temporary file, including one that was
being written when it failed, so a bake never leaves a `.…partial…` file or a 0-byte image behind,
and files already in the folder are only ever replaced by complete ones.

A process killed outright (SIGKILL, a power cut) cleans nothing: its temporaries carry its process
id, and the next bake into the folder removes those whose process is gone (`remove_stale`), never
one of a bake still writing there.
"""
from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path
from typing import Callable

try:
    import fcntl
except ImportError:  # Windows: no advisory locks on a folder
    fcntl = None


# The temporary names this module (and report.json's writers) give, `temporary`, and the folder
# probe of images.check_writable_dir: each holds the writer's process id.
_OURS = re.compile(r"\.(?:.+\.(\d+)\.partial(?:\.[A-Za-z0-9]+)?|detp_bake_probe_(\d+))")


def temporary(target: Path) -> Path:
    """The hidden name `target` is written under until it is complete: .<stem>.<pid>.partial.<ext>."""
    base, dot, ext = target.name.rpartition(".")
    name = f".{base}.{os.getpid()}.partial.{ext}" if dot else f".{target.name}.{os.getpid()}.partial"
    return target.with_name(name)


def _alive(pid: int) -> bool:
    """Whether process `pid` runs (when in doubt, yes: a live bake's file is never removed)."""
    if pid == os.getpid():
        return True
    if os.name == "nt":  # os.kill(pid, 0) would end the process there
        import ctypes
        kernel32 = ctypes.WinDLL("kernel32", use_last_error=True)
        handle = kernel32.OpenProcess(0x1000, False, pid)  # PROCESS_QUERY_LIMITED_INFORMATION
        if not handle:
            return ctypes.get_last_error() != 87  # ERROR_INVALID_PARAMETER: no such process
        code = ctypes.c_ulong()
        ok = kernel32.GetExitCodeProcess(handle, ctypes.byref(code))
        kernel32.CloseHandle(handle)
        return not ok or code.value == 259  # STILL_ACTIVE
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process: alive
        return True
    return True


def remove_stale(folder: str | os.PathLike) -> list[str]:
    """Remove the temporaries of processes that are gone from `folder` (only names this project
    gives, see `_OURS`; nothing else is touched); the names removed."""
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:  # no folder yet: nothing to clean
        return removed
    for entry in sorted(entries, key=lambda e: e.name):
        match = _OURS.fullmatch(entry.name)
        if match is None or not entry.is_file(follow_symlinks=False):
            continue
        if not _alive(int(match.group(1) or match.group(2))):
            try:
                os.unlink(entry.path)
                removed.append(entry.name)
            except OSError:
                pass  # gone already, or not ours to remove
    return removed


class FileSet:
    """Use as a context manager: on leaving it by an exception, the staged files are removed."""

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self.staged: list[tuple[Path, Path]] = []  # (temporary, target)

    def stage(self, name: str, write: Callable[[Path], None]) -> Path:
        """Call `write(temporary path)` for the file `name` in the folder; returns the target."""
        target = self.folder / name
        tmp = temporary(target)
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
