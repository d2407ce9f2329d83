"""The force one body presses on another with, along a fixed direction, from Drake's
contact results.

``ContactForceSensor`` reads the normal force of each contact, along the contact's own
normal. A force loop that presses along a planned direction (the spatial arm's tool on a
table, whose real tilt differs from the plan) reads the force along that direction instead,
friction included: what an ideal sensor aligned with the plan feels. A TemplateSystem, so
that the loop converts to AutoDiffXd (its linearization).
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import Value
from pydrake.multibody.plant import ContactResults_
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

__all__ = ["DirectionalContactForce", "DirectionalContactForce_"]


class _DirectionalContactForce:
    """The force of one body on another along a fixed unit direction, from the plant's
    point-pair contact results.

        F = - sum_c f_Tc_W . u_W        (N, > 0 while the tool presses along u)

    where f_Tc_W is the force the contact engine applies to the pressing body (the
    tool) at each of its point contacts with the pressed one (the table), and u_W the
    direction (for the spatial arm, the control frame's z: the planned inward normal,
    not the contact's own normal, which a tilted table turns): an ideal sensor's
    reading along u, friction included.

    .. pydrake_system::

        name: DirectionalContactForce
        input_ports:
        - contact_results
        output_ports:
        - contact_force
    """

    def _construct(self, tool, table, direction_W, converter=None) -> None:
        """
        Args:
            tool, table: the pressing and the pressed body's BodyIndex in the plant.
            direction_W: u_W, a unit 3-vector in world.
        """
        T = self._T
        LeafSystem_[T].__init__(self, converter=converter)
        self._tool, self._table = tool, table
        self._direction = np.asarray(direction_W, dtype=float)
        self.contact_results_input = self.DeclareAbstractInputPort(
            "contact_results", Value[ContactResults_[T]]()
        )
        self.contact_force_output = self.DeclareVectorOutputPort(
            "contact_force",
            1,
            self._CalcForce,
            prerequisites_of_calc={self.contact_results_input.ticket()},
        )

    def _construct_copy(self, other, converter=None) -> None:
        # A converted plant keeps its bodies' indices.
        _DirectionalContactForce._construct(
            self, other._tool, other._table, other._direction, converter=converter
        )

    def _CalcForce(self, context, output) -> None:
        results = self.contact_results_input.Eval(context)
        force = 0.0
        for index in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(index)
            bodies = (info.bodyA_index(), info.bodyB_index())
            if bodies == (self._table, self._tool):
                force = force - info.contact_force().dot(self._direction)
            elif bodies == (self._tool, self._table):
                force = force + info.contact_force().dot(self._direction)
        output.SetAtIndex(0, force)


@TemplateSystem.define("DirectionalContactForce_", T_list=[float, AutoDiffXd])
def DirectionalContactForce_(T):
    class Impl(_DirectionalContactForce, LeafSystem_[T]):
        __doc__ = _DirectionalContactForce.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _DirectionalContactForce._construct
        _construct_copy = _DirectionalContactForce._construct_copy

    return Impl


DirectionalContactForce = DirectionalContactForce_[None]
