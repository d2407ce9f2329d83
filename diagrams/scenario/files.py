"""Scenario files: the built-in scenarios, reading a YAML file, and loading any kind.

``load_scenario`` reads a built-in name or a YAML path, applies ``--set`` overrides, and
returns a validated scenario of the file's ``kind``, loaded by that robot's record (the
table of kinds, ``robots.kinds``). Every problem is one ``ScenarioError`` line naming the
key.
"""


# No "from __future__ import annotations": yaml_load_typed reads the real field types.

import copy
import functools
import typing
from pathlib import Path

import yaml  # PyYAML, which pydrake.common.yaml is built on
from pydrake.common.yaml import yaml_dump_typed, yaml_load

from admittance.diagrams.scenario.schema import (
    ScenarioError,
)

__all__ = [
    "builtin_scenario_names",
    "load_scenario_data",
    "scenario_file",
    "worker_source",
    "load_scenario",
    "scenario_to_yaml",
]

# The built-in scenario files (package data beside this package).
SCENARIO_DIR = Path(__file__).resolve().parents[1] / "scenarios"


# --- loading ----------------------------------------------------------------------------


def builtin_scenario_names() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def scenario_file(scenario: str) -> Path | None:
    """The YAML file behind `scenario` (as load_scenario resolves it), or None."""
    path = Path(scenario)
    if not path.suffix and scenario in builtin_scenario_names():
        return SCENARIO_DIR / f"{scenario}.yaml"
    return path.resolve() if path.is_file() else None


def worker_source(scenario: str) -> str:
    """What another process loads for `scenario`: a built-in by its name, a YAML file by its
    absolute path (the process may run in another folder)."""
    file = scenario_file(scenario)
    if file is None or file.parent == SCENARIO_DIR:
        return file.stem if file is not None else scenario
    return str(file)


def _kind_of(value) -> str:
    if isinstance(value, list):
        return "a list"
    if isinstance(value, str):
        return "a string"
    return "a number" if isinstance(value, int | float) else type(value).__name__


def _check_yaml_nodes(path: Path, text: str) -> None:
    """Raises ScenarioError for a key given twice in one mapping (YAML keeps the last one,
    silently) and for aliases (*name), which scenarios do not need."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        return  # yaml_load reports the syntax error with its line
    visited = set()
    nodes = [root] if root is not None else []
    while nodes:
        node = nodes.pop()
        at = f"line {node.start_mark.line + 1}"
        if id(node) in visited:
            raise ScenarioError(
                f"scenario: {path}: the value at {at} is repeated by an alias (*name); "
                "scenario files take no YAML aliases: write the value out"
            )
        visited.add(id(node))
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode):
                    if key.value in seen:
                        raise ScenarioError(
                            f"scenario: {path} line {key.start_mark.line + 1}: key "
                            f"{key.value!r} is given twice in the same mapping"
                        )
                    seen.add(key.value)
                nodes += [key, value]
        elif isinstance(node, yaml.SequenceNode):
            nodes += node.value


def _read_yaml(path: Path) -> dict:
    """The mapping of scenario keys in the YAML file `path`, or one ScenarioError line."""
    try:
        status = path.stat()
    except OSError as error:
        raise ScenarioError(f"scenario: {path} cannot be read: {error.strerror}") from None
    # A sweep loads the same file once per point: parse it once.
    return copy.deepcopy(_parse_yaml(path, status.st_mtime_ns, status.st_size))


@functools.lru_cache(maxsize=16)
def _parse_yaml(path: Path, modified: int, size: int) -> dict:
    try:
        raw = path.read_bytes()
    except OSError as error:
        raise ScenarioError(f"scenario: {path} cannot be read: {error.strerror}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ScenarioError(
            f"scenario: {path} is not UTF-8 text (byte 0x{raw[error.start]:02x} at offset "
            f"{error.start})"
        ) from None
    _check_yaml_nodes(path, text)
    try:
        data = yaml_load(data=text) if text.strip() else None
    except Exception as error:  # PyYAML's YAMLError (syntax) or pydrake's RuntimeError
        where = getattr(error, "problem_mark", None)
        at = f" at line {where.line + 1}, column {where.column + 1}" if where else ""
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise ScenarioError(f"scenario: {path} is not valid YAML{at}: {problem}") from None
    if data is None:
        raise ScenarioError(
            f"scenario: {path} holds no scenario keys; write the keys that differ from the "
            "defaults, or {} for every default"
        )
    if not isinstance(data, dict):
        raise ScenarioError(
            f"scenario: {path} must hold a mapping of scenario keys, got {_kind_of(data)}"
        )
    return data


def _read_source(source: str | Path | None) -> tuple[dict, str]:
    if source is None:
        return {}, "custom"
    path = Path(source)
    if not path.suffix and str(source) in builtin_scenario_names():
        path = SCENARIO_DIR / f"{source}.yaml"
    if not path.is_file():
        names = ", ".join(builtin_scenario_names())
        raise ScenarioError(
            f"scenario: '{source}' is neither a built-in scenario ({names}) nor a YAML file"
        )
    data = _read_yaml(path)
    data.setdefault("name", path.stem)
    arm = data.get("arm")
    if isinstance(arm, dict) and isinstance(arm.get("urdf"), str):
        # A URDF named relative to the scenario file: resolve it against the file's folder.
        beside = path.resolve().parent / arm["urdf"]
        if not Path(arm["urdf"]).is_absolute() and beside.is_file():
            arm["urdf"] = str(beside)
    return data, path.stem


def load_scenario(
    source: str | Path | None = None,
    overrides: typing.Sequence[str] | typing.Mapping[str, typing.Any] = (),
):
    """Loads a scenario and applies dotted-key overrides.

    Args:
        source: a built-in scenario name, a YAML path, or None for the defaults.
        overrides: "key=value" strings (as given to --set) or a {key: value} mapping.

    The file's top-level ``kind`` (default: the table's first) picks the robot, whose
    record loads the rest with its own schema and validation.

    Raises:
        ScenarioError: one line naming the first bad key and what is allowed.
    """
    data, _ = _read_source(source)
    return load_scenario_data(data, overrides)


def load_scenario_data(
    data: dict,
    overrides: typing.Sequence[str] | typing.Mapping[str, typing.Any] = (),
):
    """A validated scenario from a scenario file's mapping (its ``kind`` picks the robot)
    and dotted-key overrides.

    Raises:
        ScenarioError: one line naming the first bad key and what is allowed.
    """
    from admittance.diagrams.robots.kinds import DEFAULT_KIND, KINDS, robot

    data = dict(data)
    kind = data.pop("kind", DEFAULT_KIND)
    if not isinstance(kind, str) or kind not in KINDS:
        raise ScenarioError(f"kind: must be one of {', '.join(KINDS)}, got {kind!r}")
    return robot(kind).load(data, overrides)


def scenario_to_yaml(scenario) -> str:
    """The full scenario, every key, as YAML (written next to results)."""
    return yaml_dump_typed(scenario)
