"""A Python law's integral kept in Drake's Integrator, for a controller built as a Diagram.

A LeafSystem with its own continuous state costs three Python callbacks per derivative
evaluation (its law, its output and its derivatives). A law that outputs [y; dz/dt] in one
calc, with z an input, costs one: a ``Demultiplexer`` splits the law's output, the
``Integrator`` (a C++ primitive) holds z, and y is the Diagram's output.
"""

from __future__ import annotations

from pydrake.systems.primitives import Demultiplexer, Integrator

__all__ = ["AddLawIntegral"]


def AddLawIntegral(builder, law_output, integral_input, output_name: str) -> Integrator:
    """Wires a law's [y; dz/dt] to its integral z and exports y.

    Adds ``split`` (a Demultiplexer of `law_output` into y and dz/dt) and ``integral``
    (Drake's Integrator of dz/dt, whose state z feeds `integral_input`), and exports y as
    the Diagram's output `output_name`.

    Args:
        builder: the DiagramBuilder of the controller's Diagram.
        law_output: the law's output port [y; dz/dt].
        integral_input: the input port that reads z (its size is that of dz/dt).
        output_name: the name of the exported y.

    Returns:
        the Integrator, whose ``set_integral_value`` sets z in a context.
    """
    size = integral_input.size()
    split = builder.AddNamedSystem("split", Demultiplexer([law_output.size() - size, size]))
    integrator = builder.AddNamedSystem("integral", Integrator(size))
    builder.Connect(law_output, split.get_input_port())
    builder.Connect(split.get_output_port(1), integrator.get_input_port())
    builder.Connect(integrator.get_output_port(), integral_input)
    builder.ExportOutput(split.get_output_port(0), output_name)
    return integrator
