"""Result folders that are either complete or absent: write into a staging folder, then move.

A run writes into a hidden staging folder next to the result, ``.<name>.incomplete.<pid>.*``,
whose first file is ``INCOMPLETE`` (a plain-text failure mark). Only when every file is
written is the mark removed and the folder renamed into place (``os.replace``, atomic on
one file system). So a run killed at any moment leaves the previous complete result (or
none) under ``<name>``, and at most a hidden staging folder that says it is incomplete; the
next run into the same place removes staging folders whose process is gone.

Each command writes its folder through :func:`result_folder`, whose :class:`ResultFolder`
keeps the names of the files written, so that the command prints what it wrote and
nothing else.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from admittance.diagrams.app.interrupts import sigint_held_back

__all__ = [
    "OutputExistsError",
    "OutputPathError",
    "ResultFolder",
    "atomic_output_dir",
    "atomic_write",
    "atomic_write_text",
    "check_output_dir",
    "check_writable",
    "json_safe",
    "result_folder",
]

INCOMPLETE_MARK = "INCOMPLETE"

# The folders this process has moved into place, in order (an interrupted command names
# those it completed).
completed_folders: list[Path] = []


class OutputExistsError(FileExistsError):
    """The result folder exists and overwriting was not asked for."""


class OutputPathError(ValueError):
    """An output path that cannot be written (no such place, no permission, the current
    folder itself)."""


def check_writable(path: str | Path, flag: str = "--out") -> None:
    """Raises OutputPathError unless `path` can be created: its nearest existing folder
    takes a new entry (tried by creating and removing an empty folder there).

    Called before a run, so that a long simulation is not wasted on a refused write.
    """
    path = Path(path)
    place = path.absolute().parent
    while not place.exists() and place != place.parent:
        place = place.parent
    if not place.is_dir():
        raise OutputPathError(f"{flag} {path}: {place} is not a folder")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".admittance-probe.", dir=place))
    except OSError as error:
        raise OutputPathError(
            f"{flag} {path}: cannot write into {place}: {error.strerror}"
        ) from None


def check_output_dir(out_dir: str | Path, overwrite: bool) -> None:
    """Raises OutputExistsError if `out_dir` holds something and `overwrite` is False, and
    OutputPathError if it cannot be written or would replace the current folder.

    Called before a run, so that a long simulation is not wasted on a refused write.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise OutputExistsError(
            f"--out {out_dir}: exists; pass --force to replace it, or choose another folder"
        )
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputExistsError(f"--out {out_dir}: exists and is not a folder")
    here = Path.cwd().resolve()
    if out_dir.exists() and (out_dir.resolve() == here or out_dir.resolve() in here.parents):
        raise OutputPathError(
            f"--out {out_dir}: is the current folder or holds it; choose a folder of its own"
        )
    check_writable(out_dir)


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
        # Ctrl-C waits until the folder is in place and recorded, so that an interrupted
        # command knows whether its result was written.
        with sigint_held_back():
            mark.unlink()
            if out_dir.exists():
                old = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.old.", dir=out_dir.parent))
                os.replace(out_dir, old / out_dir.name)
                os.replace(staging, out_dir)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(staging, out_dir)
            completed_folders.append(out_dir)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


class ResultFolder:
    """The staging folder of a result being written, and the names of the files written."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.names: list[str] = []

    def write_with(self, name: str, write: Callable[[Path], None]) -> None:
        """`write(path)` writes the file `name`."""
        write(self.path / name)
        self.names.append(name)

    def write_text(self, name: str, text: str) -> None:
        self.write_with(name, lambda path: path.write_text(text))

    def write_json(self, name: str, data) -> None:
        """`data` as indented JSON, numpy scalars as numbers and non-finite floats as null."""
        self.write_text(name, json.dumps(json_safe(data), indent=2) + "\n")

    def write_figure(self, name: str, figure, dpi: int = 110) -> None:
        """Saves a matplotlib figure as `name` (PNG) and closes it."""
        import matplotlib.pyplot as plt

        figure.tight_layout()
        self.write_with(name, lambda path: figure.savefig(path, dpi=dpi))
        plt.close(figure)

    def describe(self, out_dir: str | Path) -> str:
        """``wrote DIR/: name, name, ...`` for the terminal."""
        return f"wrote {out_dir}/: {', '.join(self.names)}"


@contextmanager
def result_folder(out_dir: str | Path, overwrite: bool = True) -> Iterator[ResultFolder]:
    """:func:`atomic_output_dir` with a :class:`ResultFolder` to write into."""
    with atomic_output_dir(out_dir, overwrite=overwrite) as staging:
        yield ResultFolder(staging)


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
