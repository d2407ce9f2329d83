"""The LCM channels and messages of the hardware split, and the LCM URLs it accepts.

    PANDA_STATUS               lcmt_panda_status   station -> controller, every period
    PANDA_FT                   lcmt_force_torque   station -> controller, every period
    PANDA_COMMAND              lcmt_panda_command  controller -> station, one per status
    ADMITTANCE_PARAMETERS      JSON (UTF-8)        anyone -> controller, when changed

The parameter message is a raw LCM payload holding one JSON object with any of the keys
``force_reference``, ``gamma``, ``alpha``, ``max_force`` (numbers, in the scenario's units);
the controller applies it at its next cycle and publishes nothing back but an event line.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from drake import lcmt_panda_status

__all__ = [
    "CHANNELS",
    "Channels",
    "PARAMETER_KEYS",
    "check_lcm_url",
    "status_at_rest",
    "decode_parameters",
    "encode_parameters",
]


@dataclass(frozen=True)
class Channels:
    status: str = "PANDA_STATUS"
    command: str = "PANDA_COMMAND"
    wrench: str = "PANDA_FT"
    parameters: str = "ADMITTANCE_PARAMETERS"


CHANNELS = Channels()
# The law's parameters a running controller accepts.
PARAMETER_KEYS = ("force_reference", "gamma", "alpha", "max_force")


def encode_parameters(**values: float) -> bytes:
    """The payload of an ADMITTANCE_PARAMETERS message (checked as the controller will)."""
    payload = json.dumps(values, sort_keys=True).encode()
    decode_parameters(payload)
    return payload


def decode_parameters(payload: bytes) -> dict[str, float]:
    """The parameters of an ADMITTANCE_PARAMETERS payload.

    Raises:
        ValueError: one line naming the bad key or value.
    """
    try:
        values = json.loads(payload.decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"parameters: not a JSON object ({error})") from None
    if not isinstance(values, dict) or not values:
        raise ValueError("parameters: expected a non-empty JSON object")
    checked = {}
    for key, value in values.items():
        if key not in PARAMETER_KEYS:
            raise ValueError(
                f"parameters: unknown key {key!r}; allowed: {', '.join(PARAMETER_KEYS)}"
            )
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"parameters: {key} must be a number, got {value!r}")
        value = float(value)
        allowed = value >= 0 if key == "alpha" else value > 0
        if not allowed or (math.isinf(value) and key != "max_force") or math.isnan(value):
            raise ValueError(f"parameters: {key} out of range, got {value}")
        checked[key] = value
    return checked


def status_at_rest(utime: int, positions) -> lcmt_panda_status:
    """An ``lcmt_panda_status`` of an arm at rest at `positions` (zero velocities, torques
    and desired values), as a test or a pacer sends it."""
    message = lcmt_panda_status()
    message.utime = int(utime)
    message.num_joints = len(positions)
    message.joint_position = [float(x) for x in positions]
    for name in (
        "joint_velocity",
        "joint_position_desired",
        "joint_velocity_desired",
        "joint_acceleration_desired",
        "joint_torque",
        "joint_torque_desired",
        "joint_torque_external",
    ):
        setattr(message, name, [0.0] * len(positions))
    return message


def check_lcm_url(url: str) -> str:
    """The URL, if it keeps every packet on this machine: ``memq://``, or ``udpm://`` with
    ``ttl=0`` (multicast that never leaves the host).

    Raises:
        ValueError: one line saying what is allowed.
    """
    if url.startswith("memq://"):
        return url
    if url.startswith("udpm://") and "ttl=0" in url.split("?", 1)[-1].split("&"):
        return url
    raise ValueError(
        f"--lcm {url!r}: use memq:// (one process) or udpm://GROUP:PORT?ttl=0 (packets stay "
        "on this host); a URL with a ttl above 0 would send packets off the machine"
    )
