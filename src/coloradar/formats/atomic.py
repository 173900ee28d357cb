"""Atomic file writing: a reader never sees a half-written file, a killed writer leaves none;
and scratch files (:func:`scratch_file`) that leave nothing behind at all."""

from __future__ import annotations

import os
import re
import secrets
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

from ..errors import ColoradarError, OutputExistsError, WriteError

__all__ = ["atomic_output", "atomic_write_bytes", "atomic_write_text", "check_writable",
           "clean_partial_files", "default_file_mode",
           "is_partial_file", "make_output_dir", "new_output_path", "output_dir_error",
           "scratch_file", "write_text_if_changed"]

# atomic_write_bytes's temporary names: ".<final name>.<random>.tmp"
_PARTIAL_RE = re.compile(r"^\..+\.tmp(\.\w+)?$")


def _read_umask() -> int:
    # os.umask can only be read by setting it; done once, at import, before any worker thread
    # exists, so that no concurrent mkdir ever sees a umask of 0.
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


def default_file_mode() -> int:
    """The mode a plainly created file gets (0o666 less the umask); mkstemp would give 0o600."""
    return 0o666 & ~_UMASK


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes | memoryview) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder, then rename.

    The rename is atomic on POSIX and Windows file systems, so ``path`` holds either its old
    content or all of ``data``. The temporary name starts with ``.`` and ends with ``.tmp`` so
    that an interrupted write is recognisable and ignored by readers.
    """
    with atomic_output(path) as tmp, open(tmp, "wb") as f:
        f.write(data)


def _temporary_name(path: Path, suffix: str) -> Path:
    """``.<name>.<random>.tmp<suffix>`` beside ``path`` (a name only: the caller creates it)."""
    return path.parent / f".{path.name}.{secrets.token_hex(4)}.tmp{suffix}"


@contextmanager
def atomic_output(path: str | os.PathLike[str], suffix: str = "") -> Iterator[Path]:
    """A temporary path beside ``path`` for a writer that needs a file name (HDF5, a video, a
    Rerun recording), renamed to ``path`` when the block ends without an exception; removed
    otherwise (Ctrl-C included, also one pressed while the temporary file is being made).

    The file gets the mode a plain ``open`` would give (:func:`default_file_mode`), not
    ``mkstemp``'s 0o600. The temporary name is ``.<name>.<random>.tmp<suffix>``, recognised by
    :func:`is_partial_file` (``suffix``: for writers that choose their format by it).

    Raises
    ------
    WriteError
        The folder cannot be created, or the file cannot be written or renamed.
    """
    path = Path(path)
    tmp: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(100):
            # Named before it is created, so that a Ctrl-C landing anywhere in between still
            # leaves a name to remove (with mkstemp the name is lost if it lands in its return).
            tmp = _temporary_name(path, suffix)
            try:
                os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
                break
            except FileExistsError:
                tmp = None              # someone else's: never ours to remove
                continue
        else:
            raise FileExistsError(f"no free temporary name beside {path}")
        yield tmp
        os.chmod(tmp, default_file_mode())
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None:
            try:
                tmp.unlink(missing_ok=True)
            except OSError:
                # On a read-only file system the unlink of a name never created fails too;
                # its error would name the temporary file instead of the user's path.
                pass
        if isinstance(exc, OSError) and not isinstance(exc, ColoradarError):
            raise _write_error(path, exc) from None
        raise


def _write_error(path: Path, exc: OSError) -> WriteError:
    """A :class:`~coloradar.WriteError` naming ``path`` and why it could not be written."""
    if isinstance(exc, (FileExistsError, NotADirectoryError)):
        why = "a folder on its path is a file"
    else:
        why = str(exc.strerror or exc)
    return WriteError(f"{path}: cannot write ({why})")


def check_writable(path: str | os.PathLike[str]) -> Path:
    """Refuse, before any work, an output ``path`` (a file or a folder) that cannot be written.

    The nearest folder that exists on the way to ``path`` (``path`` itself when it is a
    folder, its parent when it is a file) is asked to create a file, which is removed at once:
    a read-only file system, a missing permission or a file where a folder must be are said
    now, naming ``path``, instead of after the work.

    Parameters
    ----------
    path
        The output file or folder, as given.

    Returns
    -------
    pathlib.Path
        ``path`` as a path.

    Raises
    ------
    WriteError
        Nothing can be created where ``path`` goes.
    """
    path = Path(path)
    near = next((q for q in (path, *path.parents) if q.exists()), Path.cwd())
    if near != path and not near.is_dir():
        raise WriteError(f"{path}: cannot write (a folder on its path, {near}, is a file)")
    folder = near if near.is_dir() else near.parent
    # A real file made and removed, not os.access: it meets what the write itself would meet
    # (a read-only mount, root squashed on NFS, ACLs), and access() answers "yes" to root.
    probe = _temporary_name(folder / path.name, "")
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError as exc:
        raise _write_error(path, exc) from None
    try:
        os.unlink(probe)
    except OSError:
        pass  # named as a partial write: readers ignore it, the next writer removes it
    return path


def make_output_dir(path: str | os.PathLike[str]) -> Path:
    """Create the output folder ``path`` (and its parents) if needed.

    Raises
    ------
    WriteError
        When ``path`` (or a parent) is a file, or it cannot be created
        (:func:`output_dir_error`).
    """
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise output_dir_error(path, exc) from None
    return path


def output_dir_error(path: Path, exc: OSError) -> WriteError:
    """The :class:`~coloradar.WriteError` for an output folder ``path`` that ``mkdir`` could not
    create: a file in its place, or why the system refused."""
    if path.exists() and not path.is_dir():
        return WriteError(f"{path}: expected an output folder, found a file")
    return _write_error(path, exc)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """:func:`atomic_write_bytes` for UTF-8 text."""
    atomic_write_bytes(path, text.encode("utf-8"))


def write_text_if_changed(path: str | os.PathLike[str], text: str) -> bool:
    """:func:`atomic_write_text`, skipped when ``path`` already holds ``text`` (keeps its
    modification time, which resumable jobs rely on). Returns whether it wrote."""
    try:
        if Path(path).read_text(encoding="utf-8") == text:
            return False
    except (OSError, UnicodeDecodeError):
        pass  # absent or unreadable: written below (which names the path if it fails)
    atomic_write_text(path, text)
    return True


def new_output_path(path: str | os.PathLike[str], overwrite: bool = False) -> Path:
    """``path`` as a :class:`~pathlib.Path` for a file about to be written; raises
    :class:`~coloradar.OutputExistsError` when it exists and ``overwrite`` is not set."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: exists; pass overwrite=True (--overwrite) to replace it")
    return path


def is_partial_file(name: str) -> bool:
    """Whether a file name is that of an interrupted atomic write (``.<name>.<random>.tmp``, see
    :func:`atomic_write_bytes`); readers ignore such files and writers may delete them."""
    return _PARTIAL_RE.match(name) is not None


def clean_partial_files(folders: Iterable[Path], name: str | None = None) -> int:
    """Delete temporary files of interrupted atomic writes (:func:`is_partial_file`) directly
    inside ``folders`` (only those of file ``name`` when given); returns how many."""
    n = 0
    for folder in folders:
        try:
            entries = list(os.scandir(folder))
        except FileNotFoundError:
            continue
        for e in entries:
            if (is_partial_file(e.name) and e.is_file()
                    and (name is None or e.name.startswith(f".{name}."))):
                try:
                    os.unlink(e.path)
                    n += 1
                except FileNotFoundError:
                    pass
    return n


def scratch_file(prefix: str) -> BinaryIO:
    """A temporary binary file (``w+b``) for data too large to keep in memory, unlinked at once:
    nothing is left behind, whatever happens to the process; closing it frees the space."""
    fd, name = tempfile.mkstemp(prefix=prefix, suffix=".bin")
    f = os.fdopen(fd, "w+b")
    os.unlink(name)
    return f
