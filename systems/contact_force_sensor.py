"""The normal force between pairs of bodies, read from Drake's contact results.

The arm's wall (systems/compliant_wall.py) computes its own force from eq. 4. A hand that
touches a real object through Drake's contact engine needs the force that engine reports:
this system reads the plant's ``contact_results`` and gives, for each watched pair of
bodies (a fingertip and the object), the compressive normal force between them. It is what
a force sensor in the fingertip would feel, before the sensor's own chain (FlexiForce).
"""

from __future__ import annotations

from collections.abc import Sequence

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import Value
from pydrake.multibody.plant import ContactModel, ContactResults_
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

__all__ = ["ContactForceSensor", "ContactForceSensor_"]


class _ContactForceSensor:
    """Normal contact force per pair of bodies, from the plant's point-pair contacts.

    For a watched pair (body P, body Q), summed over the point contacts between them:

        F_n = sum_c  -f_Bc_W . nhat_BA_W          (N, >= 0 while the bodies press)

    where, for each contact c between bodies A and B (in either order), f_Bc_W is the
    force the contact engine applies to B at the contact point and nhat_BA_W the unit
    normal pointing from B into A. The sum is the magnitude of the compressive normal
    force, whichever body Drake names A. Pairs that do not touch read 0.

    Only point contact is read (the plant's contact model must be ``kPoint``): it gives
    one normal per contact, so the normal force is exactly defined.

    .. pydrake_system::

        name: ContactForceSensor
        input_ports:
        - contact_results
        output_ports:
        - normal_force
    """

    def _construct(self, plant, *, body_pairs: Sequence[tuple[str, str]], converter=None) -> None:
        """
        Args:
            plant: the finalized MultibodyPlant_[T] whose contact results are read.
            body_pairs: (body name, body name) per output entry, e.g.
                ("finger1_tip_link", "brick_link").

        Raises:
            ValueError: a body is unknown, a pair is empty or repeated, or the plant
                does not use point contact.
        """
        LeafSystem_[self._T].__init__(self, converter=converter)
        if not plant.is_finalized():
            raise ValueError("the plant must be finalized before its contacts are read")
        if plant.get_contact_model() != ContactModel.kPoint:
            raise ValueError(
                "the contact force sensor reads point contact; the plant's contact model "
                f"is {plant.get_contact_model()}"
            )
        pairs = [tuple(pair) for pair in body_pairs]
        if not pairs:
            raise ValueError("body_pairs must name at least one pair of bodies")
        indices = []
        for first, second in pairs:
            for name in (first, second):
                if not plant.HasBodyNamed(name):
                    raise ValueError(f"the plant has no body named '{name}'")
            if first == second:
                raise ValueError(f"a pair needs two different bodies, got ('{first}', '{first}')")
            key = frozenset(
                (plant.GetBodyByName(first).index(), plant.GetBodyByName(second).index())
            )
            if key in indices:
                raise ValueError(f"the pair ('{first}', '{second}') is watched twice")
            indices.append(key)
        self._DeclarePorts(pairs, {key: slot for slot, key in enumerate(indices)})

    def _construct_copy(self, other, converter=None) -> None:
        LeafSystem_[self._T].__init__(self, converter=converter)
        self._DeclarePorts(other._body_pairs, other._pair_slot)

    def _DeclarePorts(self, pairs, pair_slot) -> None:
        self._body_pairs = list(pairs)
        # {frozenset of the two BodyIndex}: output entry.
        self._pair_slot = dict(pair_slot)
        self.contact_results_input = self.DeclareAbstractInputPort(
            "contact_results", Value[ContactResults_[self._T]]()
        )
        self.normal_force_output = self.DeclareVectorOutputPort(
            "normal_force",
            len(pairs),
            self._CalcNormalForce,
            prerequisites_of_calc={self.contact_results_input.ticket()},
        )

    @property
    def body_pairs(self) -> list[tuple[str, str]]:
        return list(self._body_pairs)

    def _CalcNormalForce(self, context, output) -> None:
        results = self.contact_results_input.Eval(context)
        forces = [self._T(0.0)] * len(self._body_pairs)
        for index in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(index)
            slot = self._pair_slot.get(frozenset((info.bodyA_index(), info.bodyB_index())))
            if slot is None:
                continue
            forces[slot] = forces[slot] - info.contact_force().dot(info.point_pair().nhat_BA_W)
        output.SetFromVector(forces)


@TemplateSystem.define("ContactForceSensor_", T_list=[float, AutoDiffXd])
def ContactForceSensor_(T):
    class Impl(_ContactForceSensor, LeafSystem_[T]):
        __doc__ = _ContactForceSensor.__doc__
        _T = T
        # TemplateSystem looks for them in the class itself.
        _construct = _ContactForceSensor._construct
        _construct_copy = _ContactForceSensor._construct_copy

    return Impl


ContactForceSensor = ContactForceSensor_[None]
