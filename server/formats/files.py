"""Reading text files with located decoding errors, and writing them atomically."""

from __future__ import annotations

import os
import tempfile

from .errors import InputError
from .limits import FILE_BYTES_MAX


def read_text(path) -> str:
    """The file's content as UTF-8 text (a leading BOM dropped); InputError if unreadable or
    larger than FILE_BYTES_MAX."""
    try:
        with open(path, "rb") as f:
            # a regular file's size sizes the buffer (read(FILE_BYTES_MAX + 1) allocates all of
            # it up front); a file without one (a pipe), or grown meanwhile, is read on
            size = os.fstat(f.fileno()).st_size
            data = f.read(min(size, FILE_BYTES_MAX) + 1) if size else b""
            if not size or len(data) > size:
                data += f.read(FILE_BYTES_MAX + 1 - len(data))
    except OSError as e:
        raise InputError(path, None, None, f"cannot read the file: {e.strerror or e}") from None
    if len(data) > FILE_BYTES_MAX:
        raise InputError(
            path, None, None, f"the file is larger than {FILE_BYTES_MAX >> 20} MiB; split it"
        )
    # Strip the BOM ourselves so that error offsets index `data` directly.
    data = data.removeprefix(b"\xef\xbb\xbf")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise InputError(
            path, line, None, f"not UTF-8 text (byte 0x{data[e.start]:02x}); save the file as UTF-8"
        ) from None


def check_writable(path) -> None:
    """InputError, before any work, if path is a folder or its folder does not exist."""
    directory = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise InputError(path, None, None, "is a folder: give a file name to write")
    if not os.path.isdir(directory):
        raise InputError(path, None, None, f"cannot write: no folder {directory}")


def ready_to_write(path) -> None:
    """Make path's folder (as write_json_atomic would) and check it can take the file; InputError
    naming path if not: for a command that records something before it writes its output."""
    directory = os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(directory, exist_ok=True)
    except OSError as e:
        why = e.strerror or str(e)
        raise InputError(path, None, None, f"cannot write: {why} ({e.filename})") from None
    check_writable(path)
    if not os.access(directory, os.W_OK):
        raise InputError(path, None, None, f"cannot write: no permission in {directory}")


def atomic_write_text(path, text: str) -> None:
    """Write text (UTF-8) to path via a temporary file in the same directory and os.replace."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    # Said up front: otherwise the error would name the temporary file, not the one asked for.
    check_writable(path)
    # mkstemp makes the file 0600; keep the mode the user had, or the usual 0644 for new files.
    try:
        mode = os.stat(path).st_mode & 0o7777
    except FileNotFoundError:
        mode = 0o644
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{os.path.basename(path)}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    _fsync_dir(directory)


def _fsync_dir(directory: str) -> None:
    # Makes the rename itself durable across a power cut; not possible on every platform.
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
