"""Plain Python float code generated from Drake symbolic expressions.

A LeafSystem's calc runs tens of thousands of times per simulation. Quantities that a
MultibodyPlant computes through its bindings (a frame's pose and Jacobian, about 10 us per
call on the planar arm) can be taken once from the plant's own symbolic model
(``plant.ToSymbolic()``) when a diagram is built, and then evaluated as straight-line
Python on floats (about 1 us): ``compile_expressions`` walks each expression with Drake's
``Expression.Unapply`` (the same walk that ``pydrake.symbolic.to_sympy`` makes), shares
repeated subexpressions, and compiles one function with Python's ``compile``.

The generated code evaluates each expression in Drake's own order (a sum as its constant
plus its terms, a product as its constant times its factors, left to right), so it gives
what ``Expression.Evaluate`` gives, at a fraction of the cost.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from pydrake.symbolic import Expression, ExpressionKind, Variable

__all__ = ["compile_expressions"]


def _ceil(value: float) -> float:
    return float(math.ceil(value))


def _floor(value: float) -> float:
    return float(math.floor(value))


# The functions the generated code may call, by the name it calls them.
_NAMESPACE = {
    "sin": math.sin,
    "cos": math.cos,
    "tan": math.tan,
    "asin": math.asin,
    "acos": math.acos,
    "atan": math.atan,
    "atan2": math.atan2,
    "sinh": math.sinh,
    "cosh": math.cosh,
    "tanh": math.tanh,
    "exp": math.exp,
    "log": math.log,
    "sqrt": math.sqrt,
    "fabs": math.fabs,
    "ceil": _ceil,
    "floor": _floor,
    "pow": math.pow,
    "min": min,
    "max": max,
}

# Expression kinds that are a call of one of those functions on the node's arguments.
_CALLS = {
    ExpressionKind.Sin: "sin",
    ExpressionKind.Cos: "cos",
    ExpressionKind.Tan: "tan",
    ExpressionKind.Asin: "asin",
    ExpressionKind.Acos: "acos",
    ExpressionKind.Atan: "atan",
    ExpressionKind.Atan2: "atan2",
    ExpressionKind.Sinh: "sinh",
    ExpressionKind.Cosh: "cosh",
    ExpressionKind.Tanh: "tanh",
    ExpressionKind.Exp: "exp",
    ExpressionKind.Log: "log",
    ExpressionKind.Sqrt: "sqrt",
    ExpressionKind.Abs: "fabs",
    ExpressionKind.Ceil: "ceil",
    ExpressionKind.Floor: "floor",
    ExpressionKind.Pow: "pow",
    ExpressionKind.Min: "min",
    ExpressionKind.Max: "max",
}


# Every kind the writer handles.
_WRITTEN = {ExpressionKind.Var, ExpressionKind.Add, ExpressionKind.Mul, ExpressionKind.Div, *_CALLS}


class _Writer:
    """Writes one expression tree as assignments, one per distinct subexpression."""

    def __init__(self, arguments: dict[int, str]) -> None:
        self.arguments = arguments  # Variable id -> argument name
        self.lines: list[str] = []
        self._names: dict[str, str] = {}  # right-hand side -> the temporary holding it

    def _temporary(self, code: str) -> str:
        name = self._names.get(code)
        if name is None:
            name = self._names[code] = f"t{len(self._names)}"
            self.lines.append(f"    {name} = {code}")
        return name

    def write(self, node) -> str:
        """A name or literal holding the value of `node` (a float or an Expression)."""
        if isinstance(node, float | int):
            return repr(float(node))
        if isinstance(node, Variable):
            return self._variable(node)
        kind = node.get_kind()
        if kind == ExpressionKind.Constant:
            return repr(float(node.Evaluate()))
        if kind not in _WRITTEN:
            raise NotImplementedError(f"no float code for a symbolic {kind.name} expression")
        _, arguments = node.Unapply()
        if kind == ExpressionKind.Var:
            return self._variable(arguments[0])
        operands = [self.write(argument) for argument in arguments]
        if kind == ExpressionKind.Add:  # constant + term + term ...
            if operands[0] in ("0.0", "-0.0"):  # x + 0 is x
                operands = operands[1:]
            code = " + ".join(operands)
        elif kind == ExpressionKind.Mul:  # constant * factor * factor ...
            if operands[0] == "1.0":  # 1 x is x
                operands = operands[1:]
            elif operands[0] == "-1.0":  # -1 x is -x
                operands = ["-" + operands[1], *operands[2:]]
            code = " * ".join(operands)
        elif kind == ExpressionKind.Div:
            code = f"{operands[0]} / {operands[1]}"
        else:
            code = f"{_CALLS[kind]}({', '.join(operands)})"
        return self._temporary(code)

    def _variable(self, variable: Variable) -> str:
        name = self.arguments.get(variable.get_id())
        if name is None:
            raise ValueError(f"the expression depends on '{variable.get_name()}', not an argument")
        return name


def compile_expressions(
    expressions: Sequence[Expression | float],
    arguments: Sequence[Variable],
    name: str = "generated",
) -> Callable[[Sequence[float]], tuple[float, ...]]:
    """One Python function that evaluates `expressions` at given values of `arguments`.

    Args:
        expressions: the values to compute (Drake Expressions, or floats for constants).
        arguments: the variables they may depend on, in the order the function takes them.
        name: the function's name (shown in tracebacks and profiles).

    Returns:
        ``function(values) -> tuple`` where ``values`` is a sequence of floats, one per
        argument, and the tuple holds one float per expression. The generated source is the
        function's ``source`` attribute.

    Raises:
        NotImplementedError: an expression uses a kind with no float equivalent here (an
            if-then-else, an uninterpreted function, NaN).
        ValueError: an expression depends on a variable that is not an argument.
    """
    parameters = [f"a{i}" for i in range(len(arguments))]
    writer = _Writer(
        {variable.get_id(): p for variable, p in zip(arguments, parameters, strict=True)}
    )
    results = [writer.write(expression) for expression in expressions]
    unpack = f"    ({', '.join(parameters)},) = values\n" if parameters else ""
    source = (
        f"def {name}(values):\n"
        + unpack
        + "".join(line + "\n" for line in writer.lines)
        + f"    return ({''.join(result + ', ' for result in results)})\n"
    )
    namespace = dict(_NAMESPACE)
    exec(compile(source, f"<generated {name}>", "exec"), namespace)  # noqa: S102
    function = namespace[name]
    function.source = source
    return function
