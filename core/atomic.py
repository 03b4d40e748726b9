"""Write files and directories so that a reader never sees them half-written.

Everything is written under a temporary name in the destination's directory and
renamed into place at the end; on error the temporary is removed.  The results
get the usual permissions (``0666``/``0777`` less the umask), not the private
``0600``/``0700`` of temporary files, so a data set written for a team is
readable by the team.

An existing destination is only ever replaced when it is of the expected kind
(a file for :func:`atomic_path`; for :func:`atomic_dir`, a directory that
`owned` recognizes as written by this tool, holding nothing but what the tool
wrote there): anything else is refused with an :class:`~eosp.errors.InputError`
before any work starts (:func:`check_output_file`, :func:`check_output_dir`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

from eosp.errors import InputError


def umask() -> int:
    """The process's umask (read without changing it for good)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _share(path: Path, directory: bool) -> None:
    """Give `path` the permissions a plain open()/mkdir() would have given it."""
    mode = (0o777 if directory else 0o666) & ~umask()
    if directory:
        for root, dirs, files in os.walk(path):
            os.chmod(root, mode)
            for f in files:
                p = os.path.join(root, f)
                if not os.path.islink(p):
                    os.chmod(p, 0o666 & ~umask())
    else:
        os.chmod(path, mode)


def _check_parent(dest: Path) -> None:
    for parent in (dest.parent, *dest.parent.parents):
        if parent.exists():
            if not parent.is_dir():
                raise InputError(dest, f"cannot write here: {parent} is a file, not a directory")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise InputError(dest, f"cannot write here: no permission to write in {parent}")
            try:
                fs = os.statvfs(parent)
            except OSError:
                return
            if fs.f_flag & os.ST_RDONLY or fs.f_blocks == 0:  # root passes os.access on /proc, /sys
                raise InputError(dest, f"cannot write here: {parent} is on a read-only filesystem or one that "
                                       "stores no files (/proc, /sys)")
            return


@contextlib.contextmanager
def _refused_by_system(dest: Path) -> Iterator[None]:
    """The system's refusal to create or rename the temporary (permission, disk full) as one line naming `dest`."""
    try:
        yield
    except InputError:
        raise
    except OSError as exc:
        raise InputError(dest, f"cannot write here: {(exc.strerror or str(exc)).lower()}") from None


def check_output_file(dest: str | os.PathLike, suffixes: Sequence[str] = (),
                      owned: Callable[[Path], bool] | None = None, what: str = "file") -> Path:
    """Refuse, before any work, an output file path that cannot or must not be written.

    `suffixes`: the accepted extensions (e.g. ``(".parquet", ".jsonl")``); `owned`: when given,
    an existing file is only replaced when ``owned(path)`` says this tool wrote it.
    """
    dest = Path(dest)
    if dest.is_dir():
        raise InputError(dest, f"is a directory: give the path of the {what} to write")
    if suffixes and dest.suffix.lower() not in suffixes:
        raise InputError(dest, f"unknown extension {dest.suffix or '(none)'!r} for a {what}: use "
                               + " or ".join(suffixes))
    if dest.exists() and not dest.is_file():
        raise InputError(dest, "exists and is not a regular file")
    if dest.exists() and owned is not None and not owned(dest):
        raise InputError(dest, f"exists and is not a {what} written by eosp: refusing to replace it")
    _check_parent(dest)
    return dest


def check_output_dir(dest: str | os.PathLike, overwrite: bool = False,
                     owned: Callable[[Path], bool] | None = None, what: str = "directory",
                     names: Callable[[Path], Iterable[str]] | None = None) -> Path:
    """Refuse, before any work, an output directory that exists (unless `overwrite` and `owned`), or that holds an
    entry the tool did not write there (`names(dest)`: the entries it wrote; a user's file put inside an output
    directory is never deleted by replacing it)."""
    dest = Path(dest)
    if dest.exists() or dest.is_symlink():
        if not dest.is_dir():
            raise InputError(dest, f"exists and is not a directory: refusing to replace it with a {what}")
        if not overwrite:
            raise InputError(dest, "already exists (use --overwrite to replace it)")
        if owned is None or not owned(dest):
            raise InputError(dest, f"exists and is not a {what} written by eosp: --overwrite only replaces those")
        if names is not None:
            _refuse_foreign(dest, set(names(dest)))
    _check_parent(dest)
    return dest


def _refuse_foreign(dest: Path, written: set[str]) -> None:
    foreign = sorted(set(os.listdir(dest)) - written)
    if foreign:
        raise InputError(dest, f"holds {foreign[0]!r}, which eosp did not write: refusing to replace the directory "
                               "(move it out first)")


@contextlib.contextmanager
def atomic_path(dest: str | os.PathLike, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary file path next to `dest`; rename it onto `dest` on success."""
    dest = Path(dest)
    if dest.is_dir():
        raise InputError(dest, "is a directory: give the path of the file to write")
    with _refused_by_system(dest):
        dest.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=suffix or ".tmp", dir=dest.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with _refused_by_system(dest):
            _share(tmp_path, directory=False)
            os.replace(tmp_path, dest)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_dir(dest: str | os.PathLike, overwrite: bool = False,
               owned: Callable[[Path], bool] | None = None,
               names: Callable[[Path], Iterable[str]] | None = None) -> Iterator[Path]:
    """Yield a temporary directory next to `dest`; move it onto `dest` on success.

    An existing `dest` is replaced only with `overwrite` and when ``owned(dest)`` (this tool wrote it), and only when
    it holds nothing but what the tool wrote (`names(dest)`; without it, what the new directory holds).
    """
    dest = Path(dest)
    check_output_dir(dest, overwrite=overwrite, owned=owned, names=names)
    with _refused_by_system(dest):
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", dir=dest.parent))
    try:
        yield tmp
        _share(tmp, directory=True)
        if dest.exists():
            check_output_dir(dest, overwrite=overwrite, owned=owned, names=names)  # it may have changed meanwhile
            _refuse_foreign(dest, set(os.listdir(tmp)) | (set(names(dest)) if names is not None else set()))
            old = Path(tempfile.mkdtemp(prefix=f".{dest.name}.old.", dir=dest.parent))
            os.replace(dest, old / "x")
            os.replace(tmp, dest)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, dest)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
