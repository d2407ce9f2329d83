"""The sweep's folder: its definition (sweep.json), its file names, and one sweep at a time.

A sweep writes into its folder as it goes, so the folder carries the result marker
(``.admittance-result``, see results/folder.py) from the start, listing every file the
sweep writes there. A sweep resumes, or with --force starts over in, only a folder that
holds nothing else: an empty one, or one whose marker lists everything in it.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
from pathlib import Path

from admittance.diagrams.app.sweep.definition import SweepDefinition
from admittance.diagrams.app.sweep.specs import SweepError
from admittance.diagrams.results.folder import (
    MARKER,
    OutputPathError,
    atomic_write_text,
    check_writable,
    foreign_entries,
    marker_entries,
    named,
    write_marker,
)

__all__ = [
    "DEFINITION_FILE",
    "LOCK_FILE",
    "PLOT_PREFIX",
    "POINTS_FILE",
    "SUMMARY_FILE",
    "TABLE_FILE",
    "check_folder",
    "finish_folder",
    "locked",
    "plot_name",
    "prepare_folder",
]

POINTS_FILE = "points.jsonl"
DEFINITION_FILE = "sweep.json"
TABLE_FILE = "table.csv"
SUMMARY_FILE = "summary.txt"
PLOT_PREFIX = "summary_"
LOCK_FILE = ".sweep.lock"
FIXED_FILES = (DEFINITION_FILE, POINTS_FILE, TABLE_FILE, SUMMARY_FILE, LOCK_FILE)
# A temporary file of atomic_write (``.<name>.<pid>.<random>.tmp``) left by a killed run.
_TEMPORARY = re.compile(r"\.(?P<name>.+)\.\d+\.[0-9a-f]{8}\.tmp")


def plot_name(key: str) -> str:
    """The summary plot of a swept key."""
    return PLOT_PREFIX + re.sub(r"[^A-Za-z0-9_.-]", "_", key) + ".png"


def _own_temporary(out_dir: Path):
    """Whether an unlisted name is a temporary file of a file the sweep writes, or its lock
    (made before the marker is written), and so the sweep's own."""
    listed = (marker_entries(out_dir) or set()) | set(FIXED_FILES) | {MARKER}

    def own(name: str) -> bool:
        match = _TEMPORARY.fullmatch(name)
        return name == LOCK_FILE or (match is not None and match["name"] in listed)

    return own


def _refuse_foreign(out_dir: Path) -> None:
    foreign = foreign_entries(out_dir, _own_temporary(out_dir))
    if foreign:
        raise SweepError(
            f"--out {out_dir}: holds files this tool did not write ({named(foreign)}); "
            "choose another folder"
        )


def check_folder(out_dir: Path, force: bool) -> None:
    """Refuses a file, a folder that holds anything this tool did not write, and (unless
    force) a folder that holds another command's result."""
    if out_dir.exists() and not out_dir.is_dir():
        raise SweepError(f"--out {out_dir}: exists and is not a folder")
    if out_dir.is_dir():
        _refuse_foreign(out_dir)
    if out_dir.is_dir() and not force and not (out_dir / DEFINITION_FILE).exists():
        if any(p.name not in (LOCK_FILE, MARKER) for p in out_dir.iterdir()):
            raise SweepError(
                f"--out {out_dir}: holds a result of this tool that is not a sweep (no "
                f"{DEFINITION_FILE}); pass --force to replace it, or choose another folder"
            )
    if not out_dir.exists():
        try:
            check_writable(out_dir)
        except OutputPathError as error:
            raise SweepError(str(error)) from None


@contextlib.contextmanager
def locked(out_dir: Path):
    """An exclusive lock on `out_dir` for the whole sweep (one sweep per folder)."""
    fd = os.open(out_dir / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise SweepError(
                f"--out {out_dir}: another sweep is running in this folder; wait for it or "
                f"choose another folder"
            ) from None
        yield
    finally:
        os.close(fd)


def _planned(definition: SweepDefinition) -> set[str]:
    """Every file a run of `definition` may write into its folder."""
    return set(FIXED_FILES) | {plot_name(key) for key in definition.keys}


def prepare_folder(definition: SweepDefinition, out_dir: Path, force: bool) -> None:
    """Checks (or, with force, clears) the folder and writes its marker and sweep.json.
    Called locked: the folder is checked once more, it may have changed since check_folder."""
    _refuse_foreign(out_dir)
    listed = marker_entries(out_dir) or set()
    own_temporary = _own_temporary(out_dir)
    for stale in out_dir.glob(".*.tmp"):  # temporary files of a killed run
        if own_temporary(stale.name):
            stale.unlink(missing_ok=True)
    wanted = definition.record()
    definition_path = out_dir / DEFINITION_FILE
    if definition_path.exists() and not force:
        try:
            stored = json.loads(definition_path.read_text()).get("definition")
        except (ValueError, AttributeError):
            stored = None
        if stored != json.loads(json.dumps(wanted)):
            differ = (
                [k for k in wanted if not isinstance(stored, dict) or stored.get(k) != wanted[k]]
                if isinstance(stored, dict)
                else ["unreadable"]
            )
            raise SweepError(
                f"--out {out_dir}: holds another sweep (its {DEFINITION_FILE} differs in: "
                f"{', '.join(differ)}); pass --force to start over, or choose another folder"
            )
    if force:  # start over: what this tool wrote here goes
        for name in sorted(listed.intersection(os.listdir(out_dir)) - {LOCK_FILE, MARKER}):
            (out_dir / name).unlink(missing_ok=True)
        listed = set()
    # Listed before they are written: a run killed at any moment leaves only listed files.
    write_marker(out_dir, (listed & set(os.listdir(out_dir))) | _planned(definition))
    document = {
        "definition": wanted,
        "scenario_path": definition.scenario_source,
        "keys": definition.keys,
        "log_keys": sorted(definition.log_keys),
        "command": "admittance sweep " + definition.describe(),
    }
    atomic_write_text(definition_path, json.dumps(document, indent=2) + "\n")


def finish_folder(definition: SweepDefinition, out_dir: Path) -> None:
    """The marker, listing the files of the folder as the finished run leaves it."""
    listed = (marker_entries(out_dir) or set()) | _planned(definition)
    write_marker(out_dir, listed & set(os.listdir(out_dir)))
