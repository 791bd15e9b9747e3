"""The four walking experiments of the thesis's chapter 5, with every parameter the text gives.

Parameters as printed in each experiment's section. Common to all four (§5.2–5.5): H = 11 steps, a = b = l/2,
step duration 0.7343 s, stance foot starting at rest at the origin (q3 = q4 = dq3 = dq4 = 0), inertias m l²/12
(not given; docs/model.md §1), Leg 2 swings first. Limits are the gaitbench defaults sized to each robot (the
thesis's were lost, docs/model.md §8). The printed initial poses are flat-ground poses; walks start from them rotated
onto the ground (``Experiment.start_state``, docs/model.md §4).
Importing this module is cheap: the experiments are built only when a factory is called.
"""

from __future__ import annotations

from gaitbench import Registration, hookimpl

STEP_DURATION = 0.7343
"""Seconds per step in all four experiments (§5.2–5.5)."""

FORWARD_CHORDS = (0.6, 0.8, 1.0, 1.4, 1.7, 1.9, 1.6, 1.3, 1.1, 0.8, 0.6)  # §5.2
DOWNWARD_CHORDS = (2.8, 2.6, 2.3, 2.15, 1.95, 1.8, 1.75, 1.35, 1.15, 1.05, 0.6)  # §5.3
UPWARD_CHORDS = (0.7, 0.8, 1.0, 1.2, 1.35, 1.45, 1.55, 1.6, 1.85, 2.1, 2.25)  # §5.4
STAIRS_RUN_RISE = (  # (L_i, H_i) in m, §5.5; D and θ follow from them (docs/model.md §4)
    (1.0, 0.6), (1.4, 0.6), (1.5, 0.8), (1.2, 0.4), (1.1, 0.5),
    (0.9, -0.8), (0.8, -1.0), (0.75, -0.7), (0.6, -0.6), (0.5, -0.6), (0.2, -0.4),
)

FORWARD_DESCRIPTION = "Flat ground, 11 steps of 0.6-1.9 m, 80 kg biped with 1 m legs (thesis §5.2)"
DOWNWARD_DESCRIPTION = "Downward slope θ = -0.677 rad, 11 steps of 2.8-0.6 m, 120 kg biped, 1.5 m legs (§5.3)"
UPWARD_DESCRIPTION = "Upward slope θ = 0.698 rad, 11 steps of 0.7-2.25 m, 110 kg biped, 1.2 m legs (§5.4)"
STAIRS_DESCRIPTION = "5 stairs up then 6 down, from (run, rise) pairs, 140 kg biped, 1 m legs (§5.5)"


def _experiment(name, description, *, M, m, l, terrain, q0, dq0, friction, source):  # noqa: E741
    """Assemble one thesis experiment; ``q0``/``dq0`` are the printed (q1, q2) and (dq1, dq2)."""
    from gaitbench.model.experiment import Experiment, FrictionParameters, Limits
    from gaitbench.model.robot import RobotParameters

    robot = RobotParameters(m1=m, m2=m, M=M, l=l, a=l / 2)
    return Experiment(
        name=name,
        description=description,
        robot=robot,
        limits=Limits.sized_for(robot),
        terrain=terrain,
        initial_state=[q0[0], q0[1], 0.0, 0.0, dq0[0], dq0[1], 0.0, 0.0],
        step_duration=STEP_DURATION,
        friction=FrictionParameters(**friction),
        source=source,
    )


def forward():
    from gaitbench.model.terrain import Terrain

    return _experiment(
        "forward", FORWARD_DESCRIPTION, M=40.0, m=20.0, l=1.0,
        terrain=Terrain.flat(FORWARD_CHORDS),
        q0=(0.2187, -0.2187), dq0=(-1.0924, -0.3774),
        friction=dict(Fc=6.0, Fs=10.0, fv=8.0, vs=0.19, Fc_lin=5.0, Fs_lin=5.0, fv_lin=6.0, vs_lin=0.03),
        source=(
            "thesis §5.2 Forward Walking (parameters, initial state and friction as printed there)"
        ),
    )


def downward_slope():
    from gaitbench.model.terrain import Terrain

    return _experiment(
        "downward-slope", DOWNWARD_DESCRIPTION, M=60.0, m=30.0, l=1.5,
        terrain=Terrain.slope(DOWNWARD_CHORDS, -0.677),
        q0=(0.4330, -0.4330), dq0=(-2.162, -0.7472),
        friction=dict(Fc=7.0, Fs=11.0, fv=9.0, vs=0.21, Fc_lin=6.0, Fs_lin=6.0, fv_lin=7.0, vs_lin=0.07),
        source=(
            "thesis §5.3 Downward Slope (parameters, θ, initial state and friction as printed there); "
            "steps 1-2 violate the printed angle bound -π/2 at heel strike, and the "
            "printed pose q2 = -q1 puts the trailing foot 0.79 m below the slope"
        ),
    )


def upward_slope():
    from gaitbench.model.terrain import Terrain

    return _experiment(
        "upward-slope", UPWARD_DESCRIPTION, M=55.0, m=27.5, l=1.2,
        terrain=Terrain.slope(UPWARD_CHORDS, 0.698),
        q0=(0.2296, -0.2296), dq0=(-1.1470, -0.3962),
        friction=dict(Fc=6.0, Fs=12.0, fv=8.5, vs=0.25, Fc_lin=6.0, Fs_lin=7.0, fv_lin=7.5, vs_lin=0.08),
        source=(
            "thesis §5.4 Upward Slope (parameters, θ, initial state and friction as printed there)"
        ),
    )


def stairs():
    from gaitbench.model.terrain import Terrain

    return _experiment(
        "stairs", STAIRS_DESCRIPTION, M=70.0, m=35.0, l=1.0,
        terrain=Terrain.stairs(STAIRS_RUN_RISE),
        q0=(0.2843, -0.2893), dq0=(-1.4201, -0.4906),
        friction=dict(Fc=7.0, Fs=10.5, fv=8.5, vs=0.21, Fc_lin=6.5, Fs_lin=6.0, fv_lin=7.0, vs_lin=0.06),
        source=(
            "thesis §5.5 Down/Up Stairs, as printed ((L, H) pairs, which win over "
            "the printed D_i/θ_i; initial state with q2 = -0.2893 kept as printed, likely a typo for "
            "-0.2843); step 7 violates the printed angle bound -π/2 at heel strike"
        ),
    )


@hookimpl
def register_experiments():
    return [
        Registration("forward", FORWARD_DESCRIPTION, forward),
        Registration("downward-slope", DOWNWARD_DESCRIPTION, downward_slope),
        Registration("upward-slope", UPWARD_DESCRIPTION, upward_slope),
        Registration("stairs", STAIRS_DESCRIPTION, stairs),
    ]
