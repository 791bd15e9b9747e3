"""An example one-off plugin: a short walk up a gentle slope, for trying gaitbench's plugin mechanism.

Load it with ``gaitbench --plugins-dir examples/plugins experiments show gentle-slope``. The factory imports
the numerics only when called, so listing plugins stays fast.
"""

from gaitbench import Registration, hookimpl


def gentle_slope():
    from gaitbench.model.experiment import Experiment
    from gaitbench.model.robot import RobotParameters
    from gaitbench.model.terrain import Terrain

    return Experiment(
        name="gentle-slope",
        description="Five 0.5 m steps up a 0.1 rad slope, 80 kg biped with 1 m legs",
        robot=RobotParameters(m1=20.0, m2=20.0, M=40.0, l=1.0, a=0.5),
        terrain=Terrain.slope([0.5] * 5, 0.1),
        initial_state=[0.2187, -0.2187, 0.0, 0.0, -1.0924, -0.3774, 0.0, 0.0],  # q1, q2, q3, q4 and rates
        step_duration=0.7343,
    )


@hookimpl
def register_experiments():
    return [Registration("gentle-slope", "Five 0.5 m steps up a 0.1 rad slope (example)", gentle_slope)]
