"""The closed loop's picture: Graphviz rendering of a built Diagram (the paper's Fig. 1).

:func:`write_diagram_picture` writes it as SVG or PNG, or its DOT source: by default a
picture that reads at a page's width (every subsystem with its connected ports, top to
bottom, without the loggers), or Drake's own full rendering.
"""

from __future__ import annotations

import html
import os
import re
import shutil
import subprocess
import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

from pydrake.systems.framework import (
    Diagram,
    InputPortIndex,
    OutputPortIndex,
    System,
)

from admittance.diagrams.views.replay import staging_path, write_atomically

__all__ = [
    "DIAGRAM_PICTURE_STYLES",
    "DIAGRAM_PICTURE_SUFFIXES",
    "DiagramPictureError",
    "readable_graphviz",
    "write_diagram_picture",
]


# ---------------------------------------------------------------------- diagram picture

#: File suffixes that `write_diagram_picture` understands.
DIAGRAM_PICTURE_SUFFIXES = (".svg", ".png", ".dot")
#: How `write_diagram_picture` draws: "readable" (`readable_graphviz`) or "drake" (Drake's
#: own `GetGraphvizString`, every port of every subsystem, loggers included).
DIAGRAM_PICTURE_STYLES = ("readable", "drake")
# Longest a Graphviz render may take, s (the closed loop takes well under one).
RENDER_TIMEOUT = 60.0
# Subsystems the readable picture leaves out: they only record signals.
_RECORDER_CLASSES = ("VectorLogSink",)
# The suffix pydrake gives the class of a system templated on its scalar type,
# e.g. "CompliantWall_𝓣float𝓤".
_SCALAR_SUFFIX = re.compile(r"_?𝓣.*𝓤$")


class DiagramPictureError(RuntimeError):
    """The diagram cannot be rendered to the requested file (one-line message)."""


def _class_name(system: System) -> str:
    """The system's class without its module and scalar type ("CompliantWall")."""
    return _SCALAR_SUFFIX.sub("", type(system).__name__)


def _port_row(system: System, kind: str, indices: list[int]) -> str:
    """One row of port cells (kind "u": inputs, "y": outputs), or "" if there are none."""
    if not indices:
        return ""
    port = system.get_input_port if kind == "u" else system.get_output_port
    cells = "".join(f'<TD PORT="{kind}{i}">{html.escape(port(i).get_name())}</TD>' for i in indices)
    return (
        '<TR><TD BORDER="0"><TABLE BORDER="0" CELLBORDER="1" CELLSPACING="0" CELLPADDING="3">'
        f"<TR>{cells}</TR></TABLE></TD></TR>"
    )


def readable_graphviz(diagram: Diagram) -> str:
    """DOT source of `diagram` that reads at a page's width.

    Drake's ``GetGraphvizString`` draws every port of every subsystem left to right: for the
    closed loop that is the MultibodyPlant's 32 ports, six loggers and class names with
    their module and scalar type, 3,500 pixels wide. This picture keeps what the loop is
    made of: every subsystem (one level deep) except the loggers (VectorLogSink), named
    as set with ``set_name`` above its class name without module or scalar type; its
    connected input ports along its top and output ports along its bottom (a grey line
    counts the ports left out); one arrow per connection; the diagram's own input and
    output ports as ellipses. The layout runs top to bottom from the subsystems without a
    connected input (the sources), so the forward path of the loop reads downwards and
    the feedback paths loop back up.
    """
    connections = diagram.connection_map()  # (system, input index) -> (system, output index)
    systems = [s for s in diagram.GetSystems() if _class_name(s) not in _RECORDER_CLASSES]
    ports = _Ports.of(diagram, connections, systems)
    order, edges = _layout(systems, connections, ports.exported_inputs)
    node = {id(s): f"s{k}" for k, s in enumerate(order)}
    lines = [
        "digraph loop {",
        "rankdir=TB",
        "nodesep=0.25",
        "ranksep=0.35",
        f"label=<<B>{html.escape(diagram.get_name())}</B>>",
        "labelloc=t",
        # A monospaced font: every renderer's substitute (Courier, DejaVu Sans Mono, Liberation
        # Mono, Menlo) has the 0.6 em advance Graphviz sized the boxes with.
        'fontname="Courier"',
        'node [shape=plaintext, fontname="Courier", fontsize=11]',
        "edge [arrowsize=0.7]",
    ]
    lines += [f"{node[id(system)]} [label=<{_node_table(system, ports)}>];" for system in order]
    for tail, tail_index, head, head_index in edges:
        lines.append(f"{node[id(tail)]}:y{tail_index}:s -> {node[id(head)]}:u{head_index}:n;")
    lines += _exported_port_lines(diagram, ports, node)
    lines.append("}")
    return "\n".join(lines) + "\n"


@dataclass
class _Ports:
    """The ports the picture draws: (id(system), index) of the connected inputs and outputs
    (the diagram's exported ones included), and the exported ports' locators."""

    inputs_used: set
    outputs_used: set
    exported_inputs: list
    exported_outputs: list

    @classmethod
    def of(cls, diagram: Diagram, connections, systems: list) -> _Ports:
        kept = {id(s) for s in systems}
        inputs_used = {(id(s), int(i)) for (s, i) in connections}
        outputs_used = {(id(s), int(i)) for (t, _), (s, i) in connections.items() if id(t) in kept}
        exported_inputs = [
            (index, diagram.GetInputPortLocators(InputPortIndex(index)))
            for index in range(diagram.num_input_ports())
        ]
        for _, locators in exported_inputs:
            inputs_used.update((id(s), int(i)) for s, i in locators)
        exported_outputs = [
            (index, diagram.get_output_port_locator(OutputPortIndex(index)))
            for index in range(diagram.num_output_ports())
        ]
        outputs_used.update((id(s), int(i)) for _, (s, i) in exported_outputs)
        return cls(inputs_used, outputs_used, exported_inputs, exported_outputs)


def _layout(systems: list, connections, exported_inputs: list) -> tuple[list, list]:
    """The subsystems in drawing order and the connections between them, sorted.

    Sources first, then breadth-first along the connections in the order of the ports:
    Graphviz breaks the loop's cycles against the order in which it meets nodes and edges,
    so the first output of a block leads (Xd into the commanded position before dXd/dt into
    the PID) and the forward path comes out downwards.
    """
    kept = {id(s) for s in systems}
    position = {id(s): k for k, s in enumerate(systems)}
    edges = sorted(
        (
            (tail, int(tail_index), head, int(head_index))
            for (head, head_index), (tail, tail_index) in connections.items()
            if id(head) in kept and id(tail) in kept
        ),
        key=lambda e: (position[id(e[0])], e[1], position[id(e[2])], e[3]),
    )
    fed = {id(head) for _, _, head, _ in edges} | {
        id(s) for _, locators in exported_inputs for s, _ in locators
    }
    order = [s for s in systems if id(s) not in fed]
    placed = {id(s) for s in order}
    for source in order:  # grows while it is walked
        for tail, _, head, _ in edges:
            if tail is source and id(head) not in placed:
                order.append(head)
                placed.add(id(head))
    order += [s for s in systems if id(s) not in placed]
    rank = {id(s): k for k, s in enumerate(order)}
    edges.sort(key=lambda e: (rank[id(e[0])], e[1], rank[id(e[2])], e[3]))
    return order, edges


def _node_table(system: System, ports: _Ports) -> str:
    """A subsystem's label: its connected inputs along the top, its name over its class
    (and how many ports are left out), its connected outputs along the bottom."""
    ins = [i for i in range(system.num_input_ports()) if (id(system), i) in ports.inputs_used]
    outs = [i for i in range(system.num_output_ports()) if (id(system), i) in ports.outputs_used]
    hidden = system.num_input_ports() + system.num_output_ports() - len(ins) - len(outs)
    rows = [
        f'<TR><TD><FONT POINT-SIZE="12"><B>{html.escape(system.get_name())}</B></FONT></TD></TR>',
        f'<TR><TD><FONT POINT-SIZE="9" COLOR="#555555">{html.escape(_class_name(system))}'
        "</FONT></TD></TR>",
    ]
    if hidden:
        rows.append(
            f'<TR><TD><FONT POINT-SIZE="9" COLOR="#777777">{hidden} unconnected ports not '
            "shown</FONT></TD></TR>"
        )
    title = (
        '<TR><TD BORDER="0"><TABLE BORDER="1" CELLBORDER="0" CELLSPACING="0" '
        f'CELLPADDING="2" BGCOLOR="#e8eef7">{"".join(rows)}</TABLE></TD></TR>'
    )
    return (
        '<TABLE BORDER="0" CELLBORDER="0" CELLSPACING="0" CELLPADDING="0">'
        f"{_port_row(system, 'u', ins)}{title}{_port_row(system, 'y', outs)}</TABLE>"
    )


def _exported_port_lines(diagram: Diagram, ports: _Ports, node: dict) -> list[str]:
    """The diagram's own input and output ports as ellipses, with their arrows."""
    lines = []
    for index, locators in ports.exported_inputs:
        name = html.escape(diagram.get_input_port(index).get_name())
        lines.append(f'in{index} [shape=ellipse, label="{name}", fontsize=11];')
        lines += [f"in{index} -> {node[id(s)]}:u{int(i)}:n;" for s, i in locators]
    for index, (system, port_index) in ports.exported_outputs:
        name = html.escape(diagram.get_output_port(index).get_name())
        lines.append(f'out{index} [shape=ellipse, label="{name}", fontsize=11];')
        lines.append(f"{node[id(system)]}:y{int(port_index)}:s -> out{index};")
    return lines


def _graphviz_command() -> str | None:
    """A Graphviz layout command: graphviz-pure (a dependency) or a system ``dot``."""
    for folder in (Path(sys.executable).parent, Path(sysconfig.get_path("scripts"))):
        candidate = folder / "graphviz-pure"
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return str(candidate)
    return shutil.which("graphviz-pure") or shutil.which("dot")


def write_diagram_picture(
    diagram: Diagram, path: str | os.PathLike, *, style: str = "readable"
) -> Path:
    """Writes the Graphviz rendering of `diagram` (subsystems one level deep).

    The format follows the suffix: ``.svg`` or ``.png`` are rendered with the
    ``graphviz-pure`` command (a dependency of this project; a system ``dot`` also works),
    ``.dot`` is the plain DOT source, which needs no renderer.

    Args:
        diagram: a built Diagram, e.g. ``BuildClosedLoop(scenario).diagram``.
        path: the file to write; its folder is created if needed.
        style: "readable" (default): `readable_graphviz`, every subsystem but the loggers
            with its connected ports, about 1,000 pixels wide for the closed loop; "drake":
            Drake's own ``GetGraphvizString(max_depth=1)``, every port and logger.

    Returns:
        The path written.

    Raises:
        ValueError: the suffix is not one of DIAGRAM_PICTURE_SUFFIXES, or the style not one
            of DIAGRAM_PICTURE_STYLES.
        DiagramPictureError: no renderer is installed, or it failed.
    """
    if style not in DIAGRAM_PICTURE_STYLES:
        raise ValueError(
            f"diagram picture style {style!r}: must be one of {', '.join(DIAGRAM_PICTURE_STYLES)}"
        )
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in DIAGRAM_PICTURE_SUFFIXES:
        raise ValueError(
            f"diagram picture {path.name!r}: the suffix must be one of "
            f"{', '.join(DIAGRAM_PICTURE_SUFFIXES)}"
        )
    if style == "readable":
        source = readable_graphviz(diagram)
    else:
        source = diagram.GetGraphvizString(max_depth=1)
    if suffix == ".dot":
        write_atomically(path, source.encode("utf-8"))
        return path

    command = _graphviz_command()
    if command is None:
        raise DiagramPictureError(
            f"cannot render {path.name}: no Graphviz command found (pip install graphviz-pure, "
            "or write the DOT source with a .dot suffix)"
        )
    # Render into a sibling temporary file, then move it into place: a failed render leaves
    # no half-written picture.
    staging = staging_path(path)
    renderer = Path(command).name
    try:
        try:
            completed = subprocess.run(
                [command, f"-T{suffix[1:]}", "-o", str(staging)],
                input=source.encode("utf-8"),
                capture_output=True,
                timeout=RENDER_TIMEOUT,
                check=False,
            )
        except (OSError, subprocess.TimeoutExpired) as error:
            raise DiagramPictureError(
                f"cannot render {path.name}: {renderer} did not run: {error}"
            ) from None
        if completed.returncode != 0 or not staging.is_file() or staging.stat().st_size == 0:
            message = completed.stderr.decode("utf-8", "replace").strip().splitlines()
            detail = message[-1] if message else f"exit status {completed.returncode}"
            raise DiagramPictureError(f"cannot render {path.name}: {renderer} failed: {detail}")
        os.replace(staging, path)
    finally:
        staging.unlink(missing_ok=True)
    return path
