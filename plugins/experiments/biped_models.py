"""The thesis's biped models: 2-DOF (stance foot pinned, First Phase) and 4-DOF (Second Phase)."""

from __future__ import annotations

from gaitbench import Registration, hookimpl


def _build(dof: int):
    def factory(robot):
        from gaitbench.model.mechanics import BipedModel

        return BipedModel(robot, dof)

    return factory


@hookimpl
def register_models():
    return [
        Registration(
            "biped-2dof", "Planar 2-leg biped, stance foot pinned: leg angles q1, q2 (First Phase)", _build(2)
        ),
        Registration(
            "biped-4dof",
            "Planar 2-leg biped with stance-foot coordinates q3, q4, exact ground "
            "reaction, push-off and heel-strike maps (Second Phase)",
            _build(4),
        ),
    ]
