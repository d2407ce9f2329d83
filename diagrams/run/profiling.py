"""Where a run's time goes: every Python callback of a diagram's LeafSystems counted and
timed (exclusive of nested callbacks), and the named subsystems of a diagram.
"""

from __future__ import annotations

import functools
import re
import time
from collections.abc import Callable

from pydrake.systems.framework import Diagram

__all__ = ["CallbackProfiler", "named_subsystems", "python_system_classes"]


# Methods of the project's LeafSystems that Drake calls back: DoCalcTimeDerivatives and
# other Do* overrides, output/cache calcs (_Calc*, _calc*) and discrete updates (*Update*).
_CALLBACK_NAME = re.compile(r"^(Do[A-Z]\w*|_\w*[Cc]alc\w*|_\w*Update\w*)$")


class CallbackProfiler:
    """Counts and times the calcs of the project's LeafSystems.

    The classes of the Python systems in a diagram are patched (before the systems are
    built, because Drake keeps the bound calc methods it is given at construction) with a
    wrapper that costs two perf_counter calls (about 1.3 us per call, against about 2 us
    for Drake to call a trivial Python calc at all). Time is exclusive of nested callbacks
    (a calc that Evals a port computed by another Python calc) and inclusive of the pydrake
    calls the calc makes itself; the C++-to-Python dispatch is not inside it.
    """

    def __init__(self) -> None:
        self.entries: dict[tuple[int, str], list] = {}  # (id(system), method) -> [calls, s]
        self.top_level_time = 0.0
        self._children: list[float] = []
        self._patched: list[tuple[type, str, object]] = []

    def _wrap(self, method_name: str, function: Callable) -> Callable:
        entries = self.entries
        children = self._children
        clock = time.perf_counter

        @functools.wraps(function)
        def wrapper(system, *args, **kwargs):
            children.append(0.0)
            start = clock()
            try:
                return function(system, *args, **kwargs)
            finally:
                elapsed = clock() - start
                nested = children.pop()
                key = (id(system), method_name)
                entry = entries.get(key)
                if entry is None:
                    entry = entries[key] = [0, 0.0]
                entry[0] += 1
                entry[1] += elapsed - nested
                if children:
                    children[-1] += elapsed
                else:
                    self.top_level_time += elapsed

        return wrapper

    def patch(self, classes: set[type]) -> None:
        """Wraps the callback methods defined by `classes` and their Python bases."""
        owners = {
            owner
            for cls in classes
            for owner in cls.__mro__
            if not owner.__module__.startswith(("pydrake", "builtins"))
        }
        for owner in owners:
            for name, attribute in list(vars(owner).items()):
                if callable(attribute) and _CALLBACK_NAME.match(name):
                    self._patched.append((owner, name, attribute))
                    setattr(owner, name, self._wrap(name, attribute))

    def restore(self) -> None:
        for owner, name, attribute in reversed(self._patched):
            setattr(owner, name, attribute)
        self._patched.clear()


def named_subsystems(diagram: Diagram, prefix: str = ""):
    """(name, system) of every system in `diagram`, inside its subdiagrams too.

    A system inside a subdiagram is named after both, e.g. ``cartesian_pid/law``.
    """
    for system in diagram.GetSystems():
        name = prefix + system.get_name()
        yield name, system
        if isinstance(system, Diagram):
            yield from named_subsystems(system, name + "/")


def python_system_classes(diagram: Diagram) -> set[type]:
    return {
        type(system)
        for _, system in named_subsystems(diagram)
        if not type(system).__module__.startswith("pydrake")
    }
