"""One writer for every output: all files of a command are checked before any work,
written to exclusive temp files, fsynced, and renamed into place together, or not at all."""

from __future__ import annotations

import hashlib
import os
import re
import secrets
import signal
import stat
import threading
import weakref
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

from .errors import OptionError, SinMDMError

# `.<name>.<pid>.<random>.part<suffix>`: the pid tells a later run whether the writer is dead,
# the random part makes the name unguessable, the suffix lets writers pick a format by it.
TEMP_NAME = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{12}\.part(\.[^.]*)?$")
PROBE_NAME = "write-check"
NAME_MAX = 255  # bytes in one file name on Linux, macOS and Windows file systems
SIGNALS_HELD_DURING_RENAME = {signal.SIGINT, signal.SIGTERM}
# Windows has neither: there a temp is still created exclusively, and renames run unmasked.
NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
CAN_MASK_SIGNALS = hasattr(signal, "pthread_sigmask")


def temp_name(name: str) -> str:
    return f".{name}.{os.getpid()}.{secrets.token_hex(6)}.part{Path(name).suffix}"


def _create_exclusive(path: Path) -> None:
    """Create an empty file that did not exist, never through a link (mode 0666 less the umask)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
    os.close(os.open(path, flags, 0o666))


def _fsync_path(path: Path, directory: bool = False) -> None:
    if directory and os.name == "nt":  # Windows cannot open a directory to sync it (NTFS renames are journaled)
        return
    flags = os.O_RDONLY | (os.O_DIRECTORY if directory else NOFOLLOW)
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    except OSError as exc:
        if not directory or exc.errno != 22:  # EINVAL: the file system cannot sync directories
            raise
    finally:
        os.close(fd)


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    except (OverflowError, OSError):
        return False
    return True


def remove_stale_temps(directory: Path) -> list[Path]:
    """Remove temp files (or planted links at temp names) whose writer's pid is dead."""
    removed = []
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return removed
    for entry in entries:
        match = TEMP_NAME.match(entry.name)
        if match and not _pid_alive(int(match["pid"])) and not entry.is_dir(follow_symlinks=False):
            try:
                os.unlink(entry.path)
                removed.append(Path(entry.path))
            except OSError:
                pass  # gone already, or not ours to remove
    return removed


def check_plain_name(name: str, option: str = "name") -> str:
    """A file name that stays inside its directory: no separators, not absolute, not '.' or '..';
    short enough that its temp name fits the file system's limit."""
    separators = {os.sep, os.altsep or os.sep, "/"}
    if not name or name in (".", "..") or "\0" in name or any(s in name for s in separators):
        raise OptionError(option, f"'{name}' is not a plain file name (no '/', '..' or absolute paths)")
    if len(os.fsencode(temp_name(name))) > NAME_MAX:
        raise OptionError(option, f"'{name[:40]}...' is too long for a file name")
    return name


def _writable_directory(directory: str | os.PathLike, option: str) -> Path:
    path = Path(directory)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OptionError(option, f"cannot create output directory {path}: {exc.strerror}") from None
    if not path.is_dir():
        raise OptionError(option, f"output path {path} is not a directory")
    probe = path / temp_name(PROBE_NAME)
    try:  # os.access says yes to root on a read-only directory: try for real
        _create_exclusive(probe)
        probe.unlink()
    except OSError as exc:
        raise OptionError(option, f"output directory {path} is not writable: {exc.strerror}") from None
    return path


def _check_target(path: Path, force: bool) -> None:
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise SinMDMError(f"cannot write {path}: {exc.strerror}") from None
    if not (stat.S_ISREG(info.st_mode) or stat.S_ISLNK(info.st_mode)):
        raise SinMDMError(f"{path} exists and is not a regular file; choose another output")
    if not force:
        raise SinMDMError(f"{path} exists; pass --force to overwrite (or choose another --out)")


def _check_free_space(directory: Path, estimate_bytes: int) -> None:
    if estimate_bytes <= 0:
        return
    try:
        info = os.statvfs(directory)
    except (OSError, AttributeError):
        return
    free = info.f_bavail * info.f_frsize
    if free < estimate_bytes:
        raise SinMDMError(f"not enough space in {directory}: about {estimate_bytes / 1e6:.1f} MB needed, "
                          f"{free / 1e6:.1f} MB free")


# --------------------------------------------------------------------------- SIGTERM while outputs are open


class _TerminationGuard:
    """While any OutputSet is open, SIGTERM raises SystemExit(143) in the main thread,
    so the temp files are removed like on KeyboardInterrupt."""

    def __init__(self) -> None:
        self.holders = 0
        self.previous = None

    @staticmethod
    def _exit(signum, frame) -> None:
        raise SystemExit(128 + signum)

    def acquire(self) -> bool:
        if threading.current_thread() is not threading.main_thread():
            return False
        if self.holders == 0:
            self.previous = signal.signal(signal.SIGTERM, self._exit)
        self.holders += 1
        return True

    def release(self) -> None:
        self.holders -= 1
        if self.holders == 0 and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, self.previous if self.previous is not None else signal.SIG_DFL)


_GUARD = _TerminationGuard()


def _discard(temps: dict[str, Path], guarded: list[bool]) -> None:
    """Remove every temp file still listed; stop holding SIGTERM. Runs once (close, exit, or collection)."""
    for tmp in temps.values():
        try:
            tmp.unlink()
        except OSError:
            pass
    temps.clear()
    if guarded and guarded.pop():
        _GUARD.release()


# --------------------------------------------------------------------------- the writer


class OutputSet:
    """Every file one command writes: checked before any work, written to exclusive temp files,
    fsynced, renamed into place together only when all succeeded, temps removed on any error,
    KeyboardInterrupt or SIGTERM."""

    def __init__(self, directory: str | os.PathLike, names: Sequence[str], *, force: bool = False,
                 estimate_bytes: int = 0, option: str = "out") -> None:
        self.names = [check_plain_name(name) for name in names]
        if len(set(self.names)) != len(self.names):
            raise SinMDMError(f"two outputs have the same name: {sorted(self.names)}")
        self.force = force
        self.directory = _writable_directory(directory, option)
        self.paths = [self.directory / name for name in self.names]
        for path in self.paths:
            _check_target(path, force)
        _check_free_space(self.directory, estimate_bytes)
        remove_stale_temps(self.directory)
        self._temps: dict[str, Path] = {}
        self._written: set[str] = set()
        self._finalizer = weakref.finalize(self, _discard, self._temps, [_GUARD.acquire()])

    @classmethod
    def for_file(cls, path: str | os.PathLike, *, force: bool = False, estimate_bytes: int = 0,
                 option: str = "out") -> "OutputSet":
        path = Path(path)
        if path.name in ("", ".", ".."):
            raise OptionError(option, f"{path} names a directory, not a file")
        return cls(path.parent, [path.name], force=force, estimate_bytes=estimate_bytes, option=option)

    def __enter__(self) -> "OutputSet":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def close(self) -> None:
        """Remove the temps of anything not committed."""
        self._finalizer()

    def path(self, name: str) -> Path:
        return self.paths[self.names.index(name)]

    @contextmanager
    def _temp(self, name: str) -> Iterator[Path]:
        """A fresh exclusive temp for `name`; removed if the block fails, fsynced if it succeeds."""
        if name not in self.names:
            raise ValueError(f"{name} is not one of the planned outputs {self.names}")
        if not self._finalizer.alive:
            raise ValueError("this OutputSet is closed")
        self._discard_temp(name)
        target = self.path(name)
        tmp = self.directory / temp_name(name)
        try:
            _create_exclusive(tmp)
            self._temps[name] = tmp
            yield tmp
            _fsync_path(tmp)  # O_NOFOLLOW: a temp swapped for a link fails here, before any rename
        except OSError as exc:
            self._discard_temp(name)
            raise SinMDMError(f"cannot write {target}: {exc.strerror or exc}") from None
        except BaseException:
            self._discard_temp(name)
            raise
        self._written.add(name)

    def _discard_temp(self, name: str) -> None:
        self._written.discard(name)
        tmp = self._temps.pop(name, None)
        if tmp is not None:
            tmp.unlink(missing_ok=True)

    def write(self, name: str, writer: Callable[[Path], None]) -> None:
        """`writer` fills the temp path it is given; any failure removes it."""
        with self._temp(name) as tmp:
            writer(tmp)

    def write_bytes(self, name: str, data: bytes) -> None:
        self.write(name, lambda tmp: tmp.write_bytes(data))

    def write_text(self, name: str, text: str) -> None:
        self.write_chunks(name, [text])

    def write_chunks(self, name: str, chunks: Iterable[str]) -> None:
        """Text written piece by piece (UTF-8), so it is never held whole."""
        def fill(tmp: Path) -> None:
            with open(tmp, "wb") as file:
                for chunk in chunks:
                    file.write(chunk.encode("utf-8"))

        self.write(name, fill)

    def commit(self) -> list[Path]:
        """Rename every written temp into place (signals held, so never half the set), fsync the directory."""
        missing = [name for name in self.names if name not in self._written]
        if missing:
            raise ValueError(f"cannot commit: {missing} not written")
        if not self.force:
            for path in self.paths:
                _check_target(path, force=False)  # another process may have written it meanwhile
        held = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS_HELD_DURING_RENAME) if CAN_MASK_SIGNALS else None
        try:
            for name, path in zip(self.names, self.paths):
                os.replace(self._temps[name], path)
                del self._temps[name]
            _fsync_path(self.directory, directory=True)
        except OSError as exc:
            raise SinMDMError(f"cannot write into {self.directory}: {exc.strerror}") from None
        finally:
            if held is not None:
                signal.pthread_sigmask(signal.SIG_SETMASK, held)
            self.close()
        return list(self.paths)


# --------------------------------------------------------------------------- single files


def file_sha256(path: str | os.PathLike) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def check_writable_dir(directory: str | os.PathLike, option: str = "out") -> Path:
    """Create `directory` if needed, check we can write into it, remove stale temps."""
    with OutputSet(directory, [], option=option) as out:
        return out.directory


@contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `target`; rename it over `target` on success."""
    with OutputSet.for_file(target, force=True) as out:
        with out._temp(out.names[0]) as tmp:
            yield tmp
        out.commit()


def write_bytes_atomic(target: str | os.PathLike, data: bytes) -> None:
    with OutputSet.for_file(target, force=True) as out:
        out.write_bytes(out.names[0], data)
        out.commit()


def write_text_atomic(target: str | os.PathLike, text: str) -> None:
    write_chunks_atomic(target, [text])


def write_chunks_atomic(target: str | os.PathLike, chunks: Iterable[str]) -> None:
    with OutputSet.for_file(target, force=True) as out:
        out.write_chunks(out.names[0], chunks)
        out.commit()
