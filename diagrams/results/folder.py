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

Every result folder carries a marker, ``.admittance-result`` (JSON: the tool, its version,
the command, the time and the entries the tool wrote there). An existing folder is replaced
only if it is empty, or carries the marker and holds nothing the marker does not list (an
entry it does not list is the user's): checked before the run (:func:`check_output_dir`)
and again at the moment of replacing, when a folder that changed meanwhile is left as it
is and the new result is kept under a new name beside it. The staging folder gets the
permissions of the umask (not tempfile's private 0700), so the result does too.
"""

from __future__ import annotations

import json
import math
import os
import shlex
import shutil
import tempfile
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from admittance.diagrams.results.interrupts import sigint_held_back

__all__ = [
    "MARKER",
    "ForeignFilesError",
    "OutputExistsError",
    "OutputPathError",
    "ResultFolder",
    "atomic_output_dir",
    "atomic_write",
    "atomic_write_text",
    "check_output_dir",
    "check_output_file",
    "check_replay_file",
    "check_writable",
    "foreign_entries",
    "json_safe",
    "marker_entries",
    "named",
    "result_folder",
    "write_marked_replay",
    "write_marker",
]

INCOMPLETE_MARK = "INCOMPLETE"
# The file that says a folder is a result of this tool, and which of its entries it wrote.
MARKER = ".admittance-result"
TOOL = "admittance"
# The command line being run (the CLI sets it), recorded in every marker.
command_line: list[str] = [TOOL]

# The folders this process has moved into place, in order (an interrupted command names
# those it completed).
completed_folders: list[Path] = []


class OutputExistsError(FileExistsError):
    """The result folder exists and overwriting was not asked for."""


class ForeignFilesError(OutputExistsError):
    """The result folder holds something this tool did not write."""


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


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("optimal-admittance")
    except PackageNotFoundError:  # pragma: no cover (running from an uninstalled tree)
        return "unknown"


def write_marker(folder: Path, entries: Iterable[str]) -> None:
    """Writes the marker of `folder`: this tool wrote `entries` there (atomically)."""
    record = {
        "tool": TOOL,
        "version": _version(),
        "command": shlex.join(command_line),
        "written": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "entries": sorted(set(entries) - {MARKER}),
    }
    atomic_write_text(folder / MARKER, json.dumps(record, indent=2) + "\n")


def marker_entries(folder: Path) -> set[str] | None:
    """The entries that the marker of `folder` lists; None without a readable marker."""
    try:
        record = json.loads((folder / MARKER).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict) or record.get("tool") != TOOL:
        return None
    entries = record.get("entries")
    if not isinstance(entries, list):
        return None
    # Plain names only: a marker is never a way to name something outside its folder.
    return {e for e in entries if isinstance(e, str) and "/" not in e and e not in ("", ".", "..")}


def foreign_entries(folder: Path, own: Callable[[str], bool] = lambda name: False) -> list[str]:
    """The entries of `folder` this tool did not write: those its marker does not list (all
    of them without a marker), and any listed one that is now a folder (the tool writes
    only files there). `own(name)` says which unlisted names are the tool's all the same."""
    names = sorted(os.listdir(folder))
    listed = marker_entries(folder)
    if listed is None:
        return [name for name in names if not own(name)]
    return [
        name
        for name in names
        if name != MARKER
        and not (name in listed and not (folder / name).is_dir())
        and not own(name)
    ]


def named(names: list[str], most: int = 3) -> str:
    """``a, b, c and 4 more``: a few names of a list for a one-line message."""
    shown = ", ".join(names[:most])
    return shown + (f" and {len(names) - most} more" if len(names) > most else "")


def _not_ours(out_dir: Path, foreign: list[str], flag: str = "--out") -> ForeignFilesError:
    return ForeignFilesError(
        f"{flag} {out_dir}: holds files this tool did not write ({named(foreign)}); "
        "choose another folder"
    )


def check_output_dir(out_dir: str | Path, overwrite: bool) -> None:
    """Raises OutputExistsError if `out_dir` holds anything this tool did not write (see
    :func:`foreign_entries`), or holds an earlier result and `overwrite` is False; and
    OutputPathError if it cannot be written or would replace the current folder. An empty
    folder is used as it is.

    Called before a run, so that a long simulation is not wasted on a refused write.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputExistsError(f"--out {out_dir}: exists and is not a folder")
    here = Path.cwd().resolve()
    if out_dir.exists() and (out_dir.resolve() == here or out_dir.resolve() in here.parents):
        raise OutputPathError(
            f"--out {out_dir}: is the current folder or holds it; choose a folder of its own"
        )
    if out_dir.is_dir():
        try:
            foreign = foreign_entries(out_dir)
        except OSError as error:
            raise OutputPathError(f"--out {out_dir}: cannot be read: {error.strerror}") from None
        if foreign:
            raise _not_ours(out_dir, foreign)
        if os.listdir(out_dir) and not overwrite:
            raise OutputExistsError(
                f"--out {out_dir}: holds an earlier result; pass --force to replace it, or "
                "choose another folder"
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


def check_output_file(
    path: str | Path, flag: str, ours: Callable[[Path], bool], what: str, overwrite: bool
) -> None:
    """Raises OutputExistsError if the single file `path` exists and is not `what` this tool
    wrote (`ours(path)` False), or is and `overwrite` is False. Called before the run and
    again just before the file is replaced."""
    path = Path(path)
    if not os.path.lexists(path):
        return
    if not path.is_file():
        raise OutputExistsError(f"{flag} {path}: exists and is not a file")
    if not ours(path):
        raise OutputExistsError(
            f"{flag} {path}: exists and is not {what} this tool wrote; choose another file"
        )
    if not overwrite:
        raise OutputExistsError(
            f"{flag} {path}: exists ({what} this tool wrote); pass --force to replace it, or "
            "choose another file"
        )


def _umask() -> int:
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):  # pragma: no cover (not Linux)
        pass
    mask = os.umask(0o022)  # pragma: no cover
    os.umask(mask)  # pragma: no cover
    return mask  # pragma: no cover


def _keep_aside(staging: Path, out_dir: Path) -> Path:
    """Moves the complete result `staging` to a new sibling of `out_dir`; returns it."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for number in range(1, 1000):
        kept = out_dir.with_name(f"{out_dir.name}.new-{stamp}" + (f"-{number}" * (number > 1)))
        try:
            kept.mkdir()
        except FileExistsError:
            continue
        os.replace(staging, kept)  # onto the empty folder just made: ours
        return kept
    raise OutputPathError(f"--out {out_dir}: no free name beside it")  # pragma: no cover


def _move_into_place(staging: Path, out_dir: Path) -> None:
    """Replaces `out_dir` (absent, empty, or an earlier result of this tool) by `staging`.

    Checked again here, since a long run gives the user time to put files into `out_dir`:
    if it now holds something this tool did not write, it is left as it is, the new result
    is kept beside it, and OutputExistsError says where.
    """
    foreign: list[str] = []
    if os.path.lexists(out_dir):
        foreign = foreign_entries(out_dir) if out_dir.is_dir() else [out_dir.name]
    if not foreign and os.path.lexists(out_dir):
        old = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.old.", dir=out_dir.parent))
        os.replace(out_dir, old / out_dir.name)
        # What was moved is what gets deleted: look at it once more, out of the way.
        foreign = foreign_entries(old / out_dir.name)
        if foreign:
            try:
                os.replace(old / out_dir.name, out_dir)
            except OSError:  # pragma: no cover (yet another folder appeared there meanwhile)
                raise OutputExistsError(
                    f"--out {out_dir}: changed during the run; its files are in "
                    f"{old / out_dir.name}/, the new result is in {_keep_aside(staging, out_dir)}/"
                ) from None
            old.rmdir()
        else:
            os.replace(staging, out_dir)
            shutil.rmtree(old, ignore_errors=True)
            return
    if not foreign:
        try:
            os.replace(staging, out_dir)
            return
        except OSError:  # a folder appeared meanwhile and is not empty
            foreign = foreign_entries(out_dir) if out_dir.is_dir() else [out_dir.name]
    kept = _keep_aside(staging, out_dir)
    raise OutputExistsError(
        f"--out {out_dir}: changed during the run and now holds files this tool did not "
        f"write ({named(foreign)}); left as it is, the new result is in {kept}/"
    )


@contextmanager
def atomic_output_dir(out_dir: str | Path, overwrite: bool = True) -> Iterator[Path]:
    """Yields a staging folder next to `out_dir`; on success it replaces `out_dir`.

    On any error (or interruption) the staging folder is removed and `out_dir` is left as
    it was, so a reader never sees a half-written result. With `overwrite` False an existing
    `out_dir` raises OutputExistsError before anything is written. An `out_dir` holding
    anything this tool did not write is left as it is, and the result kept beside it (see
    :func:`_move_into_place`): the commands refuse such a folder before their run (with
    :func:`check_output_dir`), so here it has changed since. The result carries the
    marker, listing every file in it.
    """
    out_dir = Path(out_dir)
    try:
        check_output_dir(out_dir, overwrite)
    except ForeignFilesError:
        # The command checked before its run: the folder changed since. The result is
        # written all the same, and kept beside the folder (see _move_into_place).
        pass
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_staging(out_dir)
    staging = Path(
        tempfile.mkdtemp(prefix=f".{out_dir.name}.incomplete.{os.getpid()}.", dir=out_dir.parent)
    )
    staging.chmod(0o777 & ~_umask())  # mkdtemp's folders are private
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
            write_marker(staging, os.listdir(staging))
            _move_into_place(staging, out_dir)
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


# The last line of a Meshcat replay this tool wrote (an HTML comment after the document):
# the sign that --meshcat-html may replace the file.
REPLAY_MARK = "<!-- admittance-replay: a Meshcat replay written by admittance simulate -->"


def _is_marked_replay(path: Path) -> bool:
    with open(path, "rb") as file:
        file.seek(max(0, path.stat().st_size - 4096))
        return REPLAY_MARK.encode() in file.read()


def check_replay_file(path: str | Path, force: bool) -> None:
    """--meshcat-html FILE replaces only a replay this tool wrote, and only with --force."""
    check_output_file(path, "--meshcat-html", _is_marked_replay, "a Meshcat replay", force)


def write_marked_replay(replay, result, path: Path, force: bool, out: Path) -> None:
    """`replay(result, file)` into a hidden sibling of `path`, marked, then moved onto
    `path` if it may still be replaced (the file may have changed during the run)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp.html")
    try:
        replay(result, temporary)
        with open(temporary, "a") as file:
            file.write(REPLAY_MARK + "\n")
        try:
            check_replay_file(path, force)
        except OutputExistsError as error:
            raise OutputExistsError(
                f"{error} (it changed during the run; the new replay was discarded, the "
                f"result folder {out}/ was written)"
            ) from None
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)
