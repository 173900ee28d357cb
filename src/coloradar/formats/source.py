"""Uniform read access to a folder or to a ``.zip`` archive, without extracting anything.

ColoRadar runs and the calibration are shipped as zips; users also unpack them. A
:class:`Source` hides the difference: files are addressed by POSIX paths relative to the source's
root (``"cascade/adc_samples/timestamps.txt"``), whatever the zip's own top folder is.
"""

from __future__ import annotations

import errno
import os
import stat
import threading
import zipfile
from collections.abc import Iterable
from pathlib import Path, PurePosixPath

from ..errors import FormatError, MissingDataError, ReadError

__all__ = ["FolderSource", "Source", "ZipSource", "check_input_path", "check_regular_file",
           "open_source", "read_file_bytes", "read_file_text"]

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"))


def _not_regular(path: Path, mode: int) -> ReadError:
    kind = next((what for test, what in _KINDS if test(mode)), "not a regular file")
    return ReadError(f"{path}: expected a regular file, found {kind}")


def _stat(p: Path) -> os.stat_result:
    """``os.stat`` with its failures as named coloradar errors."""
    try:
        return os.stat(p)
    except FileNotFoundError:
        raise MissingDataError(f"{p}: file not found") from None
    except OSError as exc:
        raise ReadError(f"{p}: cannot be read ({exc.strerror or exc})") from None


def check_regular_file(path: str | os.PathLike[str]) -> int:
    """The size of ``path`` in bytes, after checking that it is a regular file.

    Raises
    ------
    MissingDataError
        When ``path`` does not exist.
    ReadError
        When it is not a regular file (a FIFO would block a reader forever) or cannot be
        examined.
    """
    p = Path(path)
    st = _stat(p)
    if not stat.S_ISREG(st.st_mode):
        raise _not_regular(p, st.st_mode)
    return st.st_size


def read_file_bytes(path: str | os.PathLike[str]) -> bytes:
    """The whole content of the regular file ``path``.

    The file is opened without blocking and checked on the open descriptor, so that a FIFO or
    a device put in place of a data file is refused at once instead of hanging the reader.

    Raises
    ------
    MissingDataError
        When ``path`` does not exist.
    ReadError
        When it is not a regular file or cannot be read (permissions, I/O error).
    """
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except FileNotFoundError:
        raise MissingDataError(f"{p}: file not found") from None
    except IsADirectoryError:
        raise ReadError(f"{p}: expected a regular file, found a folder") from None
    except OSError as exc:
        raise ReadError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise _not_regular(p, mode)
        with os.fdopen(fd, "rb") as f:
            fd = -1
            return f.read()
    except OSError as exc:
        if isinstance(exc, ReadError):
            raise
        raise ReadError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    finally:
        if fd >= 0:
            os.close(fd)


def read_file_text(path: str | os.PathLike[str]) -> str:
    """:func:`read_file_bytes` decoded as UTF-8; :class:`FormatError` when it is not text."""
    try:
        return read_file_bytes(path).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(f"{path}: expected a UTF-8 text file ({exc})") from None


class Source:
    """Read-only access to a tree of files, addressed by relative POSIX paths."""

    #: What the source is, for messages: a folder path, or ``archive.zip:prefix/``.
    location: str

    def exists(self, rel: str) -> bool:
        """True when the file or folder ``rel`` exists."""
        raise NotImplementedError

    def is_dir(self, rel: str) -> bool:
        """True when ``rel`` is a folder (for zips: when some member lies under it)."""
        raise NotImplementedError

    def listdir(self, rel: str = "") -> list[str]:
        """Names (not paths) of the entries directly inside folder ``rel``, sorted."""
        raise NotImplementedError

    def read_bytes(self, rel: str) -> bytes:
        """The whole content of file ``rel``; :class:`MissingDataError` when absent."""
        raise NotImplementedError

    def read_text(self, rel: str) -> str:
        """The content of text file ``rel`` decoded as UTF-8."""
        try:
            return self.read_bytes(rel).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FormatError(f"{self.describe(rel)}: expected a UTF-8 text file ({exc})") from None

    def file_size(self, rel: str) -> int:
        """Size of file ``rel`` in bytes (uncompressed size for zips)."""
        raise NotImplementedError

    def describe(self, rel: str) -> str:
        """A human-readable name of file ``rel`` for error messages."""
        raise NotImplementedError

    def version_key(self, rel: str) -> str:
        """A short text that changes whenever file ``rel`` is rewritten (size and modification
        time; for zip members size, CRC and date), without reading it: what a resumable job
        compares to tell whether an input changed since its output was made."""
        raise NotImplementedError

    def sub(self, rel: str) -> Source:
        """The source rooted at sub-folder ``rel``."""
        raise NotImplementedError


class FolderSource(Source):
    """A :class:`Source` over a folder of the file system."""

    def __init__(self, root: str | os.PathLike[str]):
        self.root = Path(root)
        self.location = str(self.root)

    def _p(self, rel: str) -> Path:
        return self.root / rel if rel else self.root

    def exists(self, rel: str) -> bool:
        return self._p(rel).exists()

    def is_dir(self, rel: str) -> bool:
        return self._p(rel).is_dir()

    def listdir(self, rel: str = "") -> list[str]:
        p = self._p(rel)
        if not p.is_dir():
            raise MissingDataError(f"{p}: folder not found")
        return sorted(os.listdir(p))

    def read_bytes(self, rel: str) -> bytes:
        return read_file_bytes(self._p(rel))

    def file_size(self, rel: str) -> int:
        return check_regular_file(self._p(rel))

    def version_key(self, rel: str) -> str:
        st = _stat(self._p(rel))
        return f"{st.st_size}:{st.st_mtime_ns}"

    def describe(self, rel: str) -> str:
        return str(self._p(rel))

    def sub(self, rel: str) -> FolderSource:
        return FolderSource(self._p(rel))

    def path(self, rel: str) -> Path:
        """The file-system path of ``rel`` (folder sources only)."""
        return self._p(rel)

    def __repr__(self) -> str:
        return f"FolderSource({self.location!r})"


class _ZipIndex:
    """The member list of one archive, opened lazily and re-opened after a fork."""

    def __init__(self, path: Path):
        self.path = path
        self._lock = threading.Lock()
        self._zf: zipfile.ZipFile | None = None
        self._pid = -1
        try:
            with zipfile.ZipFile(path) as zf:
                infos = zf.infolist()
        except (zipfile.BadZipFile, OSError) as exc:
            raise FormatError(f"{path}: expected a readable zip archive ({exc})") from None
        self.sizes: dict[str, int] = {}
        self.versions: dict[str, str] = {}
        self.dirs: dict[str, set[str]] = {"": set()}
        for info in infos:
            name = info.filename.rstrip("/")
            if not name:
                continue
            parts = PurePosixPath(name).parts
            for i in range(len(parts)):
                parent = "/".join(parts[:i])
                self.dirs.setdefault(parent, set()).add(parts[i])
            if info.is_dir():
                self.dirs.setdefault(name, set())
            else:
                self.sizes[name] = info.file_size
                self.versions[name] = f"{info.file_size}:{info.CRC:08x}:{info.date_time}"

    def read(self, name: str) -> bytes:
        with self._lock:
            if self._zf is None or self._pid != os.getpid():
                self._zf = zipfile.ZipFile(self.path)
                self._pid = os.getpid()
            return self._zf.read(name)

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_zf"] = None
        state["_lock"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()


class ZipSource(Source):
    """A :class:`Source` over a zip archive (or a folder inside one), read in place."""

    def __init__(self, archive: str | os.PathLike[str], prefix: str = "",
                 _index: _ZipIndex | None = None):
        self.archive = Path(archive)
        self._index = _index if _index is not None else _ZipIndex(self.archive)
        self.prefix = prefix.strip("/")
        self.location = f"{self.archive}:{self.prefix}/" if self.prefix else str(self.archive)

    def _n(self, rel: str) -> str:
        rel = rel.strip("/")
        if self.prefix:
            return f"{self.prefix}/{rel}" if rel else self.prefix
        return rel

    def exists(self, rel: str) -> bool:
        n = self._n(rel)
        return n in self._index.sizes or n in self._index.dirs

    def is_dir(self, rel: str) -> bool:
        return self._n(rel) in self._index.dirs

    def listdir(self, rel: str = "") -> list[str]:
        n = self._n(rel)
        if n not in self._index.dirs:
            raise MissingDataError(f"{self.describe(rel)}: folder not found in archive")
        return sorted(self._index.dirs[n])

    def read_bytes(self, rel: str) -> bytes:
        n = self._n(rel)
        if n not in self._index.sizes:
            raise MissingDataError(f"{self.describe(rel)}: file not found in archive")
        return self._index.read(n)

    def file_size(self, rel: str) -> int:
        n = self._n(rel)
        if n not in self._index.sizes:
            raise MissingDataError(f"{self.describe(rel)}: file not found in archive")
        return self._index.sizes[n]

    def describe(self, rel: str) -> str:
        return f"{self.archive}:{self._n(rel)}"

    def version_key(self, rel: str) -> str:
        n = self._n(rel)
        if n not in self._index.versions:
            raise MissingDataError(f"{self.describe(rel)}: file not found in archive")
        return self._index.versions[n]

    def sub(self, rel: str) -> ZipSource:
        return ZipSource(self.archive, self._n(rel), _index=self._index)

    def __repr__(self) -> str:
        return f"ZipSource({self.location!r})"


def check_input_path(path: str | os.PathLike[str],
                     expected: str = "a folder or a zip archive") -> None:
    """Check that ``path`` is a folder or a readable zip archive, with an error that says what
    it really is otherwise.

    Raises
    ------
    MissingDataError
        Nothing there; or a symbolic link that leads nowhere (a loop, or a missing target),
        said as such.
    ReadError
        Something that is neither a folder nor a regular file (a FIFO, a socket, a device), or
        that cannot be examined.
    FormatError
        A regular file that is not a zip archive; a zip archive cut short (a copy or a download
        that did not finish) is said to be one.
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        if p.is_symlink():
            raise MissingDataError(f"{p}: a symbolic link to {os.readlink(p)}, which does not "
                                   f"exist; expected {expected}") from None
        raise MissingDataError(f"{p}: no such folder or zip file") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise MissingDataError(f"{p}: a loop of symbolic links (it never reaches a file or "
                                   f"folder); expected {expected}") from None
        raise ReadError(f"{p}: cannot be examined ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        return
    if not stat.S_ISREG(st.st_mode):
        kind = next((what for test, what in _KINDS if test(st.st_mode)), "not a regular file")
        raise ReadError(f"{p}: {kind}; expected {expected}")
    if zipfile.is_zipfile(p):
        return
    try:
        with open(p, "rb") as f:
            head = f.read(4)
    except OSError as exc:
        raise ReadError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    if head == b"PK\x03\x04":
        raise FormatError(f"{p}: a zip archive cut short or damaged ({st.st_size:,} bytes, no "
                          "table of contents at its end; a copy or download that did not "
                          "finish?); copy it again")
    what = "an empty file" if st.st_size == 0 else f"a file of {st.st_size:,} bytes"
    raise FormatError(f"{p}: {what} that is not a zip archive; expected {expected}")


def open_source(path: str | os.PathLike[str], markers: Iterable[str] = ()) -> Source:
    """Open a folder or a zip as a :class:`Source`.

    For a zip, when ``markers`` are given and none lies at the archive's top level but all lie in
    its single top folder (``run0.zip`` holding ``run0/cascade/…``), the source is rooted there.

    Parameters
    ----------
    path
        A folder or a ``.zip`` file.
    markers
        Names expected at the root of the tree (e.g. ``("cascade", "imu")``).
    """
    p = Path(path)
    if p.is_dir():
        return FolderSource(p)
    check_input_path(p)  # zipfile would block on a FIFO
    src = ZipSource(p)
    markers = tuple(markers)
    top = src.listdir("")
    if markers and not any(m in top for m in markers):
        dirs = [t for t in top if src.is_dir(t) and not t.startswith("__MACOSX")]
        if len(dirs) == 1:
            return src.sub(dirs[0])
    return src
