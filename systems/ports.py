"""Writing a LeafSystem's vector output from a calc that runs once per evaluation."""

from __future__ import annotations

__all__ = ["set_output"]


def set_output(T, output, values) -> None:
    """Writes `values` (a sequence of T) into a vector output port's value.

    For double, through the output's writable numpy view: about half the cost of
    ``SetFromVector`` on a Python sequence. Other scalar types use ``SetFromVector``.
    """
    if T is float:
        output.get_mutable_value()[:] = values
    else:
        output.SetFromVector(values)
