"""Reading a Meshcat replay back: the commands a static HTML file carries, and its tracks.

Shared by the arm's and the hand's replay tests.
"""

from __future__ import annotations

import base64
import re

import msgpack

# Each recorded Meshcat command is a base64 msgpack blob fetched from a data: URL.
DATA_COMMAND = re.compile(r'fetch\("data:application/octet-binary;base64,([A-Za-z0-9+/=]*)"\)')


def replay_commands(html: str) -> list[dict]:
    """The decoded Meshcat commands of a replay's HTML, in order."""
    return [
        msgpack.unpackb(base64.b64decode(data), strict_map_key=False)
        for data in DATA_COMMAND.findall(html)
    ]


def replay_tracks(commands) -> dict[tuple[str, str], list[dict]]:
    """(path, property) -> keyframes of the one recorded animation."""
    (animation,) = [c for c in commands if c["type"] == "set_animation"]
    return {
        (entry["path"], track["name"].lstrip(".")): track["keys"]
        for entry in animation["animations"]
        for track in entry["clip"]["tracks"]
    }
