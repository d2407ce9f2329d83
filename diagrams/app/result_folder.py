"""Result folders that are either complete or absent: write into a staging folder, then move.

A run writes into a hidden staging folder next to the result, ``.<name>.incomplete.<pid>.*``,
whose first file is ``INCOMPLETE`` (a plain-text failure mark). Only when every file is
written is the mark removed and the folder renamed into place (``os.replace``, atomic on
one file system). So a run killed at any moment leaves the previous complete result (or
none) under ``<name>``, and at most a hidden staging folder that says it is incomplete; the
next run into the same place removes staging folders whose process is gone.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = [
    "OutputExistsError",
    "atomic_output_dir",
    "atomic_write",
    "atomic_write_text",
    "check_output_dir",
    "json_safe",
]

INCOMPLETE_MARK = "INCOMPLETE"


class OutputExistsError(FileExistsError):
    """The result folder exists and overwriting was not asked for."""


def check_output_dir(out_dir: str | Path, overwrite: bool) -> None:
    """Raises OutputExistsError if `out_dir` holds something and `overwrite` is False.

    Called before a run, so that a long simulation is not wasted on a refused write.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise OutputExistsError(
            f"--out {out_dir}: exists; pass --force to replace it, or choose another folder"
        )
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputExistsError(f"--out {out_dir}: exists and is not a folder")


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, owned by someone else
        return True
    return True


def _remove_stale_staging(out_dir: Path) -> None:
    """Removes staging folders of `out_dir` left by runs that were killed."""
    prefix = f".{out_dir.name}.incomplete."
    for candidate in out_dir.parent.glob(prefix + "*"):
        pid_text = candidate.name[len(prefix) :].split(".", 1)[0]
        if pid_text.isdigit() and not _process_alive(int(pid_text)):
            shutil.rmtree(candidate, ignore_errors=True)


@contextmanager
def atomic_output_dir(out_dir: str | Path, overwrite: bool = True) -> Iterator[Path]:
    """Yields a staging folder next to `out_dir`; on success it replaces `out_dir`.

    On any error (or interruption) the staging folder is removed and `out_dir` is left as
    it was, so a reader never sees a half-written result. With `overwrite` False an existing
    `out_dir` raises OutputExistsError before anything is written.
    """
    out_dir = Path(out_dir)
    check_output_dir(out_dir, overwrite)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_staging(out_dir)
    staging = Path(
        tempfile.mkdtemp(prefix=f".{out_dir.name}.incomplete.{os.getpid()}.", dir=out_dir.parent)
    )
    mark = staging / INCOMPLETE_MARK
    mark.write_text(
        f"This folder is being written by process {os.getpid()} and is not a result.\n"
        f"If that process is gone, it was interrupted: this folder can be deleted.\n"
    )
    try:
        yield staging
        mark.unlink()
        if out_dir.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.old.", dir=out_dir.parent))
            os.replace(out_dir, old / out_dir.name)
            os.replace(staging, out_dir)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(staging, out_dir)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def json_safe(value):
    """`value` with numpy scalars as Python numbers and non-finite floats as None (JSON)."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, np.generic):
        return json_safe(value.item())
    return value


def atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    """Writes one file atomically: write(temporary path next to it), fsync, os.replace.

    The temporary file is ``.<name>.<pid>.<random>.tmp`` in the same folder; on any error
    it is removed and `path` is left as it was.
    """
    # Not mkstemp: its files are private (0600); these get the umask's usual permissions.
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        write(temporary)
        with open(temporary, "rb") as file:
            os.fsync(file.fileno())
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """`path` holds `text` afterwards, or is left as it was."""
    atomic_write(path, lambda temporary: temporary.write_text(text))
