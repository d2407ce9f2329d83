"""The sweep's folder: its definition (sweep.json), its file names, and one sweep at a time."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
from pathlib import Path

from admittance.diagrams.app.result_folder import (
    OutputPathError,
    atomic_write_text,
    check_writable,
)
from admittance.diagrams.app.sweep.definition import SweepDefinition
from admittance.diagrams.app.sweep.specs import SweepError

__all__ = [
    "DEFINITION_FILE",
    "LOCK_FILE",
    "PLOT_PREFIX",
    "POINTS_FILE",
    "SUMMARY_FILE",
    "TABLE_FILE",
    "check_folder",
    "locked",
    "prepare_folder",
]

POINTS_FILE = "points.jsonl"
DEFINITION_FILE = "sweep.json"
TABLE_FILE = "table.csv"
SUMMARY_FILE = "summary.txt"
PLOT_PREFIX = "summary_"
LOCK_FILE = ".sweep.lock"


def check_folder(out_dir: Path, force: bool) -> None:
    """Refuses a file, or a folder that holds something other than a sweep (unless force)."""
    if out_dir.exists() and not out_dir.is_dir():
        raise SweepError(f"--out {out_dir}: exists and is not a folder")
    if out_dir.is_dir() and not force and not (out_dir / DEFINITION_FILE).exists():
        if any(p.name != LOCK_FILE for p in out_dir.iterdir()):
            raise SweepError(
                f"--out {out_dir}: exists and is not a sweep folder (no {DEFINITION_FILE}); "
                f"choose another folder or pass --force"
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


def _sweep_files(out_dir: Path) -> list[Path]:
    names = [DEFINITION_FILE, POINTS_FILE, TABLE_FILE, SUMMARY_FILE]
    files = [out_dir / name for name in names if (out_dir / name).exists()]
    files += sorted(out_dir.glob(f"{PLOT_PREFIX}*.png"))
    return files


def prepare_folder(definition: SweepDefinition, out_dir: Path, force: bool) -> None:
    """Checks (or, with force, clears) the folder and writes sweep.json. Called locked."""
    for stale in out_dir.glob(".*.tmp"):  # temporary files of a killed run
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
    if force:
        for file in _sweep_files(out_dir):
            file.unlink()
    document = {
        "definition": wanted,
        "scenario_path": definition.scenario_source,
        "keys": definition.keys,
        "log_keys": sorted(definition.log_keys),
        "command": "admittance sweep " + definition.describe(),
    }
    atomic_write_text(definition_path, json.dumps(document, indent=2) + "\n")
