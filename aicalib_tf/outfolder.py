"""An output folder replaced as a whole: a reader sees the old set of files or the new one, never a mix.

A run opens its ``--out`` with :class:`OutputFolder` before any work, so a bad folder fails at
once (a file, a path under a file, a read-only parent, a name too long, a broken link, or a
folder holding files that aicalib_tf did not write). The run writes every file into a staging
folder beside ``--out`` (:attr:`OutputFolder.path`), and :meth:`OutputFolder.commit` swaps it in:

* on Linux by one ``renameat2(RENAME_EXCHANGE)``, which exchanges the two folders atomically;
* elsewhere by two renames (old folder aside, new one in); a run killed between them leaves the
  old folder under its aside name, and the next run into the same ``--out`` puts it back first.

A lock file beside the folder (``.aicalib-<hash>.lock``, ``flock``) keeps two runs from writing
one ``--out`` at the same time: the second fails with a clear error. Staging folders left by
killed runs are removed by the next run that takes the lock.

**Whose files are whose.** A marker file (``.aicalib``, JSON ``{"kind", "files"}``) in every folder
written this way lists the names the run wrote there. A later run replaces exactly those: a file or
folder the user added since (``notes.txt`` beside the calibration) is **kept**, carried into the new
folder before the swap (as a hard link, or a copy where links cannot be made), so the swap stays
atomic and a run killed at any moment loses none of the user's files. A user's file with the name
of one the new run writes is not overwritten: the run fails with an error naming it, and the old
folder stays as it was. An existing folder without the marker is replaced only when it holds
nothing but the files an older aicalib_tf wrote (:data:`_KNOWN_NAMES`); otherwise the run is
refused before any work. A marker of an older version (no file list) counts the same known names
as the run's own.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import hashlib
import os
import shutil
import tempfile
from pathlib import Path

__all__ = ["OutputFolder", "MARKER", "check_out_path"]

MARKER = ".aicalib"  # written into every output folder; its presence makes the folder replaceable
_MARKER_BYTES = 16 << 20  # a marker larger than this is not read (its folder's files count as the user's)
_RENAME_EXCHANGE = 2  # linux/fs.h
_AT_FDCWD = -100
# Files an older calibration folder (written before the marker existed) may hold.
_KNOWN_NAMES = ("camera.yaml", "camera.json", "camera_info.yaml", "report.png", "report.txt", "rig.json",
                "intrinsics.yml", "extrinsics.yml", "camchain.yaml", "check.json")


def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return 255


def check_out_path(out) -> Path:
    """The absolute ``--out`` folder, after the checks that need no writing; OSError/ValueError naming it.

    Refused: an empty name, an existing non-folder (a file, ``/dev/null``), a broken symbolic
    link, a path under a file, a name longer than the file system allows.
    """
    text = os.fspath(out)
    if not str(text).strip():
        raise ValueError("--out: an empty folder name")
    path = Path(os.path.abspath(text))
    if path.is_symlink() and not path.exists():
        raise ValueError(f"{out}: a broken symbolic link; remove it or choose another --out")
    path = path.resolve() if path.is_symlink() else path
    if path.exists() and not path.is_dir():
        raise ValueError(f"{out}: exists and is not a folder")
    ancestor = path.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ValueError(f"{out}: {ancestor} is not a folder")
    limit = _name_max(ancestor)
    for part in path.parts:
        if len(os.fsencode(part)) > limit:
            raise OSError(errno.ENAMETOOLONG, os.strerror(errno.ENAMETOOLONG), str(out))
    if path == Path(path.anchor):
        raise ValueError(f"{out}: the root folder cannot be an output folder")
    return path


def _ours(name: str) -> bool:
    """Whether a name is one an older aicalib_tf (before the marker listed its files) may have written."""
    return name in _KNOWN_NAMES or (name.startswith("undistorted_") and name.endswith(".png"))


def _foreign_entries(path: Path) -> list[str]:
    """Entries of an existing folder without the marker that show it is not aicalib_tf's to replace."""
    try:
        names = sorted(os.listdir(path))
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    if not names or MARKER in names:
        return []
    return [n for n in names if not _ours(n)]


def _marker(kind: str, files: list[str]) -> str:
    """The marker file's text: what the folder holds and the names the run wrote into it."""
    from aicalib_tf.jsonio import dumps

    return dumps({"kind": kind, "files": files}) + "\n"


def _user_entries(path: Path) -> list[str]:
    """Entries of a marked folder that the run which wrote it did not write (the user's, to keep)."""
    try:
        names = sorted(os.listdir(path))
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    if MARKER not in names:
        return []
    try:
        from aicalib_tf.jsonio import loads, read_text

        written = loads(read_text(path / MARKER, max_bytes=_MARKER_BYTES), str(path / MARKER)).get("files")
    except (OSError, ValueError, AttributeError):  # an older marker (one line, the kind), or not ours
        written = None
    if not isinstance(written, list) or not all(isinstance(n, str) for n in written):
        return [n for n in names if n != MARKER and not _ours(n)]
    return [n for n in names if n != MARKER and n not in set(written)]


def _carry(src: Path, dst: Path) -> None:
    """Put ``src`` (a file, link or folder) at ``dst`` by hard links, copying where a link cannot be made."""
    def link_or_copy(a, b):
        try:
            os.link(a, b, follow_symlinks=False)
        except OSError:
            shutil.copy2(a, b, follow_symlinks=False)

    try:
        if src.is_dir() and not src.is_symlink():
            shutil.copytree(src, dst, symlinks=True, copy_function=link_or_copy)
        else:
            link_or_copy(src, dst)
    except (OSError, shutil.Error) as exc:
        raise OSError(errno.EIO, f"cannot keep the file aicalib_tf did not write ({exc}); nothing was replaced",
                      str(src)) from None


class OutputFolder:
    """A staging folder for one run's files, swapped in for ``out`` by :meth:`commit`.

    Use as a context manager: the swap happens on a clean exit; on an exception the staging
    folder is removed and ``out`` is left as it was. ``kind`` names what the folder holds, for
    the marker file.
    """

    def __init__(self, out, kind: str = "output"):
        self.out = check_out_path(out)
        self.kind = kind
        parent = self.out.parent
        parent.mkdir(parents=True, exist_ok=True)
        self._tag = ".aicalib-" + hashlib.sha256(os.fsencode(self.out.name)).hexdigest()[:12]
        self._lock_fd = self._lock(parent / f"{self._tag}.lock")
        try:
            self._recover_and_clean(parent)
            foreign = _foreign_entries(self.out) if self.out.is_dir() else []
            if foreign:
                shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
                raise ValueError(f"{out}: the folder holds files aicalib_tf did not write ({shown}); "
                                 "choose a new or empty --out, so that nothing of yours is replaced")
            self.path = Path(tempfile.mkdtemp(prefix=f"{self._tag}.tmp-", dir=parent))
            (self.path / MARKER).write_text(_marker(kind, []), encoding="utf-8")  # its file list at commit
        except BaseException:
            self._unlock()
            raise
        self._done = False

    def _lock(self, lock_path: Path) -> int:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ValueError(f"{self.out}: another run is writing this folder now; wait for it or choose another --out") from None
        return fd

    def _unlock(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing releases the flock
            self._lock_fd = None

    def _recover_and_clean(self, parent: Path) -> None:
        """Put back a folder a killed swap left aside; remove staging folders of killed runs."""
        aside = sorted(parent.glob(f"{self._tag}.old-*"))
        if aside and not self.out.exists():
            os.rename(aside.pop(), self.out)
        for stale in aside + sorted(parent.glob(f"{self._tag}.tmp-*")):
            shutil.rmtree(stale, ignore_errors=True)

    def commit(self) -> Path:
        """Swap the staging folder in for ``out``; returns ``out``. The old run's files are removed, the
        user's kept (module docstring); ValueError naming a user's file that the run would overwrite."""
        if self._done:
            return self.out
        try:
            self._seal()
            if not self.out.exists():
                os.rename(self.path, self.out)
            elif not _exchange(self.path, self.out):
                aside = Path(tempfile.mkdtemp(prefix=f"{self._tag}.old-", dir=self.out.parent))
                os.rename(self.out, aside)  # a folder may replace an empty one
                os.rename(self.path, self.out)
                shutil.rmtree(aside, ignore_errors=True)
            else:
                shutil.rmtree(self.path, ignore_errors=True)  # now holds the old files
            _fsync_dir(self.out.parent)
        except BaseException:
            shutil.rmtree(self.path, ignore_errors=True)
            raise
        finally:
            self._done = True
            self._unlock()
        return self.out

    def _seal(self) -> None:
        """Write the marker (the names this run wrote) and carry the user's files of ``out`` into the staging folder."""
        written = sorted(n for n in os.listdir(self.path) if n != MARKER)
        (self.path / MARKER).write_text(_marker(self.kind, written), encoding="utf-8")
        keep = _user_entries(self.out) if self.out.is_dir() else []
        clash = sorted(set(keep) & set(written))
        if clash:
            raise ValueError(f"{self.out / clash[0]}: a file aicalib_tf did not write has the name of one this run "
                             "writes; move it away (or choose another --out) and run again; nothing was replaced")
        for name in keep:
            _carry(self.out / name, self.path / name)

    def abort(self) -> None:
        """Remove the staging folder and leave ``out`` as it was."""
        if not self._done:
            shutil.rmtree(self.path, ignore_errors=True)
            self._done = True
        self._unlock()

    def __enter__(self) -> "OutputFolder":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.abort()


def _exchange(a: Path, b: Path) -> bool:
    """Exchange two paths atomically (Linux renameat2); False where the system cannot."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
