"""The planar two-leg biped of the thesis, derived symbolically for both stance cases and both models.

Conventions (docs/model.md §1): q1, q2 are absolute leg angles from the vertical, counter-clockwise positive;
leg labels are fixed and roles alternate (``stance`` is the label of the stance leg, 1 or 2). The 4-DOF
model adds the stance-foot position (q3, q4); the 2-DOF model pins the stance foot at the origin.
Kinematics ("Convention A"): hip = foot + l(−sin q_st, cos q_st), swing foot = hip + l(sin q_sw, −cos q_sw).

Every function takes the robot parameter vector ``p = (m1, m2, M, l, a, I1, I2, g)`` as its last input, so one
symbolic build serves every robot (the energetics study varies masses and lengths) and transcriptions can
call the same functions on symbolic arguments.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import casadi as ca

from gaitbench.model.mechanics.lagrangian import derive

N_PARAMETERS = 8


def _cross(r: ca.SX, v: ca.SX) -> ca.SX:
    return r[0] * v[1] - r[1] * v[0]


def _direction_up(angle: ca.SX) -> ca.SX:
    """Unit vector from a foot towards the hip for a leg at this absolute angle."""
    return ca.vertcat(-ca.sin(angle), ca.cos(angle))


@dataclass(frozen=True)
class _Geometry:
    """Positions in Convention A for a stance case: the three masses and the swing foot."""

    com_stance: ca.SX
    hip: ca.SX
    com_swing: ca.SX
    swing_foot: ca.SX


def _geometry(q: ca.SX, foot: ca.SX, stance: int, l: ca.SX, a: ca.SX) -> _Geometry:
    st, sw = (0, 1) if stance == 1 else (1, 0)
    up_st = _direction_up(q[st])
    down_sw = -_direction_up(q[sw])
    hip = foot + l * up_st
    return _Geometry(com_stance=foot + a * up_st, hip=hip, com_swing=hip + (l - a) * down_sw,
                     swing_foot=hip + l * down_sw)


@dataclass(frozen=True)
class BipedFunctions:
    """CasADi functions of one model (2 or 4 DOF) in one stance case.

    Inputs are named ``q``, ``dq``, ``tau`` (the two hip torques), ``impulse`` and ``p``. Functions absent from a
    model are ``None``: the 2-DOF model has no push-off (its stance foot cannot move) and no ground reaction.
    """

    dof: int
    stance: int
    mass: ca.Function  # (q, p) -> M
    coriolis: ca.Function  # (q, dq, p) -> C
    gravity: ca.Function  # (q, p) -> G
    mass_derivative: ca.Function  # (q, dq, p) -> Ṁ
    kinetic_energy: ca.Function  # (q, dq, p) -> K
    potential_energy: ca.Function  # (q, p) -> P
    hip: ca.Function  # (q, p) -> (x, y)
    swing_foot: ca.Function  # (q, p) -> (x, y)
    swing_foot_jacobian: ca.Function  # (q, p) -> ∂Y/∂q
    forward_dynamics: (
        ca.Function
    )  # (q, dq, tau, p) -> (ddq, ground reaction (horizontal f_x, vertical f_y)) ; 2-DOF: ground reaction = 0
    heel_strike: ca.Function  # (q, dq, p) -> (dq⁺, impact impulse at the swing foot (x, y))
    angular_momentum_about_swing_foot: ca.Function  # (q, dq, p) -> scalar
    push_off: ca.Function | None  # (q, dq, impulse, p) -> dq⁺ ; 4-DOF only


@cache
def biped_functions(dof: int, stance: int) -> BipedFunctions:
    """Build (once per process) the symbolic model for ``dof`` in {2, 4} with leg ``stance`` in {1, 2} on the ground."""
    if dof not in (2, 4):
        raise ValueError(f"dof must be 2 or 4, got {dof}")
    if stance not in (1, 2):
        raise ValueError(f"stance leg must be 1 or 2, got {stance}")

    p = ca.SX.sym("p", N_PARAMETERS)
    m1, m2, hip_mass, l, a, inertia1, inertia2, g = (p[i] for i in range(N_PARAMETERS))
    q = ca.SX.sym("q", dof)
    dq = ca.SX.sym("dq", dof)
    tau = ca.SX.sym("tau", 2)

    m_st, m_sw = (m1, m2) if stance == 1 else (m2, m1)
    geometry = _geometry(q, q[2:4] if dof == 4 else ca.SX.zeros(2), stance, l, a)
    hip, swing_foot = geometry.hip, geometry.swing_foot
    points = ((m_st, geometry.com_stance), (hip_mass, hip), (m_sw, geometry.com_swing))

    def velocity(point: ca.SX) -> ca.SX:
        return ca.jtimes(point, q, dq)

    kinetic = 0.5 * (inertia1 * dq[0] ** 2 + inertia2 * dq[1] ** 2)
    kinetic += sum(0.5 * mass * ca.sumsqr(velocity(point)) for mass, point in points)
    potential = sum(mass * g * point[1] for mass, point in points)
    eom = derive(q, dq, kinetic, potential)
    bias = ca.mtimes(eom.coriolis, dq) + eom.gravity

    inputs = ca.vertcat(tau, ca.SX.zeros(dof - 2))
    if dof == 4:
        # Stance foot held by a holonomic constraint: the ground reaction is the exact multiplier (docs/model.md §2).
        select = ca.horzcat(ca.SX.zeros(2, 2), ca.SX.eye(2))
        kkt = ca.blockcat([[eom.mass, -select.T], [select, ca.SX.zeros(2, 2)]])
        solution = ca.solve(kkt, ca.vertcat(inputs - bias, ca.SX.zeros(2)))
        ddq, reaction = solution[:dof], solution[dof:]
    else:
        ddq, reaction = ca.solve(eom.mass, inputs - bias), ca.SX.zeros(2)

    # Heel strike: plastic impact at the swing foot, the old stance foot free (docs/model.md §3).
    jac = ca.jacobian(swing_foot, q)
    momentum = _angular_momentum(points, velocity, swing_foot, dq, inertia1, inertia2)
    if dof == 4:
        impact = ca.blockcat([[eom.mass, -jac.T], [jac, ca.SX.zeros(2, 2)]])
        solution = ca.solve(impact, ca.vertcat(ca.mtimes(eom.mass, dq), ca.SX.zeros(2)))
        dq_plus, impact_impulse = solution[:dof], solution[dof:]
    else:
        dq_plus, impact_impulse = _angular_momentum_impact_map(
            q, dq, stance, l, a, m1, m2, hip_mass, inertia1, inertia2
        )

    push_off = None
    if dof == 4:
        impulse = ca.SX.sym("impulse")
        # Scalar impulse along the stance leg, from the foot towards the hip: J_PO = [0, 0, −sin q_st, cos q_st].
        direction = ca.vertcat(0, 0, _direction_up(q[stance - 1]))
        dq_push = dq + ca.solve(eom.mass, direction * impulse)
        push_off = ca.Function(
            "push_off", [q, dq, impulse, p], [dq_push], ["q", "dq", "impulse", "p"], ["dq_plus"]
        )

    def fn(name: str, args: list, outs: list, arg_names: list[str], out_names: list[str]) -> ca.Function:
        return ca.Function(name, args, outs, arg_names, out_names)

    return BipedFunctions(
        dof=dof,
        stance=stance,
        mass=fn("mass", [q, p], [eom.mass], ["q", "p"], ["M"]),
        coriolis=fn("coriolis", [q, dq, p], [eom.coriolis], ["q", "dq", "p"], ["C"]),
        gravity=fn("gravity", [q, p], [eom.gravity], ["q", "p"], ["G"]),
        mass_derivative=fn("mass_derivative", [q, dq, p], [eom.mass_derivative], ["q", "dq", "p"], ["dM"]),
        kinetic_energy=fn("kinetic_energy", [q, dq, p], [kinetic], ["q", "dq", "p"], ["K"]),
        potential_energy=fn("potential_energy", [q, p], [potential], ["q", "p"], ["P"]),
        hip=fn("hip", [q, p], [hip], ["q", "p"], ["hip"]),
        swing_foot=fn("swing_foot", [q, p], [swing_foot], ["q", "p"], ["Y"]),
        swing_foot_jacobian=fn("swing_foot_jacobian", [q, p], [jac], ["q", "p"], ["E"]),
        forward_dynamics=fn(
            "forward_dynamics",
            [q, dq, tau, p],
            [ddq, reaction],
            ["q", "dq", "tau", "p"],
            ["ddq", "ground_reaction"],
        ),
        heel_strike=fn(
            "heel_strike", [q, dq, p], [dq_plus, impact_impulse], ["q", "dq", "p"], ["dq_plus", "impulse"]
        ),
        angular_momentum_about_swing_foot=fn(
            "angular_momentum_about_swing_foot", [q, dq, p], [momentum], ["q", "dq", "p"], ["H"]
        ),
        push_off=push_off,
    )


def _angular_momentum(points, velocity, pivot, dq, inertia1, inertia2) -> ca.SX:
    """Total angular momentum of the biped about a point fixed in space that coincides with ``pivot``."""
    total = inertia1 * dq[0] + inertia2 * dq[1]
    for mass, point in points:
        total += mass * _cross(point - pivot, velocity(point))
    return total


def _angular_momentum_impact_map(q, dq, stance, l, a, m1, m2, hip_mass, inertia1, inertia2):
    """The First Phase's classic impact map Q⁺ q̇⁺ = Q⁻ q̇⁻ (thesis (2.24)–(2.26), corrected).

    Row 1: total angular momentum about the striking foot is conserved (the only impulse acts there).
    Row 2: angular momentum of the old stance leg about the hip is conserved (it receives impulses only at the
    hip once its foot lifts off). Both are built from the geometry with a free stance foot (x, y), so neither
    Q⁺ nor Q⁻ is typed in; after impact the new stance foot is at rest, which fixes ẋ, ẏ.
    """
    st = 0 if stance == 1 else 1
    m_st, m_sw = (m1, m2) if stance == 1 else (m2, m1)
    inertia_st = inertia1 if stance == 1 else inertia2
    ext_q = ca.vertcat(q, ca.SX.sym("foot", 2))
    ext_dq = ca.SX.sym("ext_dq", 4)
    geometry = _geometry(ext_q, ext_q[2:4], stance, l, a)
    com_st, hip, com_sw, striking_foot = geometry.com_stance, geometry.hip, geometry.com_swing, geometry.swing_foot

    def velocity(point: ca.SX) -> ca.SX:
        return ca.jtimes(point, ext_q, ext_dq)

    points = ((m_st, com_st), (hip_mass, hip), (m_sw, com_sw))
    total = _angular_momentum(points, velocity, striking_foot, ext_dq, inertia1, inertia2)
    old_stance_about_hip = inertia_st * ext_dq[st] + m_st * _cross(com_st - hip, velocity(com_st))
    momentum = ca.vertcat(total, old_stance_about_hip)
    rates = ca.jacobian(momentum, ext_dq)  # momentum is linear in the velocities
    q_minus = rates[:, :2]  # before impact the stance foot is at rest
    striking_jacobian = ca.jacobian(striking_foot, ext_q)
    # After impact the striking foot is at rest: foot velocity = −E_angles q̇ (E_foot is the identity).
    q_plus = rates[:, :2] - ca.mtimes(rates[:, 2:], striking_jacobian[:, :2])
    q_plus = ca.substitute(q_plus, ext_q[2:4], ca.SX.zeros(2))
    q_minus = ca.substitute(q_minus, ext_q[2:4], ca.SX.zeros(2))
    dq_plus = ca.solve(q_plus, ca.mtimes(q_minus, dq))
    # The impulse on the striking foot equals the change of total linear momentum.
    linear_rates = ca.jacobian(sum(mass * velocity(point) for mass, point in points), ext_dq)
    foot_velocity_after = -ca.mtimes(striking_jacobian[:, :2], dq_plus)
    momentum_after = ca.mtimes(linear_rates, ca.vertcat(dq_plus, foot_velocity_after))
    momentum_before = ca.mtimes(linear_rates, ca.vertcat(dq, ca.SX.zeros(2)))
    impulse = ca.substitute(momentum_after - momentum_before, ext_q[2:4], ca.SX.zeros(2))
    return dq_plus, impulse
