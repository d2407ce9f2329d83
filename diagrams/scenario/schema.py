"""Scenarios: typed YAML descriptions of one closed-loop run (docs/reference/scenarios.md).

A scenario is a tree of dataclasses loaded with Drake's ``yaml_load_typed``. Every field has
a default equal to the paper's value (Section VII-A); the built-in scenarios in
``diagrams/scenarios/`` override what differs. ``--set key=value`` overrides use the dotted
key of a field (``wall.stiffness``, ``admittance.gamma``, ...).

Every problem with user input raises ``ScenarioError`` with one line that names the key and
what is allowed; nothing deeper than this module sees unvalidated values.
"""


# No "from __future__ import annotations": yaml_load_typed reads the real field types.

import dataclasses
import math
import typing

import yaml  # PyYAML, which pydrake.common.yaml is built on
from pydrake.common.yaml import yaml_load, yaml_load_typed

from admittance.diagrams.scenario.key_hints import unknown_key_hint

__all__ = [
    "INTEGRATION_SCHEMES",
    "ScenarioError",
    "check_tree",
    "coerce_numbers",
    "load_typed",
    "parse_overrides",
    "parse_value",
    "scenario_keys",
    "set_dotted",
    "to_yaml_text",
    "unknown_key_error",
]


class ScenarioError(ValueError):
    """A scenario key has a missing, unknown, mistyped or impossible value."""


# --- keys and types ---------------------------------------------------------------------

INTEGRATION_SCHEMES = (
    "bogacki_shampine3",
    "explicit_euler",
    "implicit_euler",
    "radau1",
    "radau3",
    "runge_kutta2",
    "runge_kutta3",
    "runge_kutta5",
    "semi_explicit_euler",
    "velocity_implicit_euler",
)


def _fields_of(schema) -> dict[str, typing.Any]:
    """Field name -> type for a dataclass or a Drake config struct (SimulatorConfig)."""
    if dataclasses.is_dataclass(schema):
        hints = typing.get_type_hints(schema)
        return {f.name: hints[f.name] for f in dataclasses.fields(schema)}
    return {f.name: f.type for f in schema.__fields__}


def _is_struct(kind) -> bool:
    return dataclasses.is_dataclass(kind) or hasattr(kind, "__fields__")


def scenario_keys(schema, prefix: str = "") -> dict[str, typing.Any]:
    """All dotted leaf keys of the scenario with their types."""
    keys = {}
    for name, kind in _fields_of(schema).items():
        key = prefix + name
        if _is_struct(kind):
            keys.update(scenario_keys(kind, key + "."))
        else:
            keys[key] = kind
    return keys


def _describe(kind) -> str:
    origin = typing.get_origin(kind)
    if origin is list:
        (item,) = typing.get_args(kind)
        return f"a list of {_describe(item)}"
    summary = getattr(kind, "ENTRY_SUMMARY", None)
    if summary is not None:
        return summary
    return {
        float: "a number",
        int: "an integer",
        bool: "true or false",
        str: "a string",
    }.get(kind, getattr(kind, "__name__", str(kind)))


def _check_entry_complete(key: str, entry: dict, kind) -> None:
    """Raises ScenarioError naming the first field that a list entry leaves out.

    A list entry's dataclass names the fields an entry must give (``required_fields``):
    left out, they would silently take the dataclass's default.
    """
    required = getattr(kind, "required_fields", None)
    if required is None:
        return
    for name in required(entry):
        if name not in entry:
            raise ScenarioError(f"{key}.{name}: missing; {kind.MISSING_HINT}")


def _check_type(key: str, value, kind):
    """Returns `value` converted to `kind`, or raises ScenarioError naming `key`."""
    origin = typing.get_origin(kind)
    if origin is list:
        (item,) = typing.get_args(kind)
        if not isinstance(value, list):
            raise ScenarioError(f"{key}: expected {_describe(kind)}, got {value!r}")
        return [_check_type(f"{key}[{i}]", v, item) for i, v in enumerate(value)]
    if dataclasses.is_dataclass(kind):
        if not isinstance(value, dict):
            raise ScenarioError(f"{key}: expected a mapping of {_describe(kind)}, got {value!r}")
        fields = _fields_of(kind)
        for name in value:
            if name not in fields:
                raise ScenarioError(
                    f"{key}.{name}: unknown key; allowed: {', '.join(sorted(fields))}"
                )
        _check_entry_complete(key, value, kind)
        return {name: _check_type(f"{key}.{name}", v, fields[name]) for name, v in value.items()}
    if kind is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false"):
            return value.lower() == "true"
        raise ScenarioError(f"{key}: expected true or false, got {value!r}")
    if kind in (int, float):
        expected = "an integer" if kind is int else "a number"
        if kind is int and isinstance(value, int) and not isinstance(value, bool):
            return value  # exactly: a float holds integers exactly only up to 2**53
        number = None
        if not isinstance(value, bool):
            try:
                number = float(value)
            except (TypeError, ValueError):
                pass
            except OverflowError:  # an integer beyond a float: out of every range
                number = math.inf if value > 0 else -math.inf
        if number is None or math.isnan(number) or (kind is int and not number.is_integer()):
            raise ScenarioError(f"{key}: expected {expected}, got {value!r}")
        return int(number) if kind is int else number
    if kind is str:
        if not isinstance(value, str):
            raise ScenarioError(f"{key}: expected a string, got {value!r}")
        return value
    raise ScenarioError(f"{key}: cannot be set")  # pragma: no cover (no other leaf types)


def unknown_key_error(key: str, valid: typing.Iterable[str]) -> ScenarioError:
    return ScenarioError(f"{key}: unknown scenario key{unknown_key_hint(key, valid)}")


def parse_value(text: str):
    """Parses a --set value: a number, true/false, a string, or a YAML list/mapping."""
    stripped = text.strip()
    if stripped[:1] in ("[", "{"):
        try:
            return yaml_load(data=f"value: {stripped}")["value"]
        except (RuntimeError, yaml.YAMLError) as error:
            problem = getattr(error, "problem", None) or str(error).splitlines()[0]
            raise ScenarioError(f"cannot parse {text!r} as YAML: {problem}") from None
    for convert in (int, float):
        try:
            return convert(stripped)
        except ValueError:
            pass
    if stripped.lower() in ("true", "false"):
        return stripped.lower() == "true"
    if stripped.lower() in (".inf", "inf"):
        return math.inf
    return stripped


def parse_overrides(overrides: typing.Sequence[str]) -> list[tuple[str, typing.Any]]:
    """(key, value) pairs of "KEY=VALUE" strings (as given to --set), values parsed."""
    pairs = []
    for text in overrides:
        key, sep, value = text.partition("=")
        if not sep or not key.strip():
            raise ScenarioError(f"--set {text!r}: expected KEY=VALUE")
        try:
            pairs.append((key.strip(), parse_value(value)))
        except ScenarioError as error:
            raise ScenarioError(f"{key.strip()}: {error}") from None
    return pairs


def coerce_numbers(value):
    """YAML leaves numbers such as 1e5 as strings; turn numeric strings into floats."""
    if isinstance(value, dict):
        return {k: coerce_numbers(v) for k, v in value.items()}
    if isinstance(value, list):
        return [coerce_numbers(v) for v in value]
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def check_tree(data: dict, schema, prefix: str = "", valid: typing.Iterable[str] = ()) -> dict:
    """`data` checked against `schema`; `valid` (the root's keys) names the close matches."""
    fields = _fields_of(schema)
    valid = valid or scenario_keys(schema)
    checked = {}
    for name, value in data.items():
        key = prefix + name
        if name not in fields:
            raise unknown_key_error(key, valid)
        kind = fields[name]
        if _is_struct(kind):
            if not isinstance(value, dict):
                raise ScenarioError(f"{key}: expected a mapping, got {value!r}")
            checked[name] = check_tree(value, kind, key + ".", valid)
        else:
            checked[name] = _check_type(key, value, kind)
    return checked


def set_dotted(data: dict, key: str, value) -> None:
    node = data
    parts = key.split(".")
    for part in parts[:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ScenarioError(f"{key}: cannot set inside a non-mapping value")
    node[parts[-1]] = value


def to_yaml_text(data: dict) -> str:
    import json

    # JSON is YAML; inf is spelled .inf in YAML.
    text = json.dumps(data, allow_nan=True)
    return text.replace("Infinity", ".inf")


def load_typed(
    data: dict,
    schema,
    overrides: typing.Sequence[str] | typing.Mapping[str, typing.Any] = (),
):
    """An instance of `schema` from a YAML file's mapping and dotted-key overrides.

    Every key is checked against `schema` (unknown keys with a hint of the close ones,
    types, list entries), then loaded with Drake's ``yaml_load_typed``. Ranges and the
    checks that relate keys are the caller's (each robot's validation).

    Args:
        overrides: "key=value" strings (as given to --set) or a {key: value} mapping; a
            key may name a whole section or list (wall.stiffness_steps=[...]).

    Raises:
        ScenarioError: one line naming the first bad key and what is allowed.
    """
    data = coerce_numbers(dict(data))
    items = overrides.items() if isinstance(overrides, typing.Mapping) else None
    if items is None:
        items = parse_overrides(overrides)
    valid = scenario_keys(schema)
    for key, value in items:
        if key not in valid:
            # Allow whole sub-trees such as wall.stiffness_steps.
            sections = {k.rsplit(".", i)[0] for k in valid for i in range(1, k.count(".") + 1)}
            if key not in sections:
                raise unknown_key_error(key, valid)
        set_dotted(data, key, value)
    checked = check_tree(data, schema, valid=valid)
    return yaml_load_typed(schema=schema, data=to_yaml_text(checked))
