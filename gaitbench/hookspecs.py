"""Every plugin kind and the hook a gaitbench plugin implements to register things of that kind, declared in one place.

A plugin is a module (or object) with functions decorated by ``gaitbench.hookimpl`` whose names match the
specifications below. Each hook takes no arguments and returns a list of :class:`gaitbench.Registration`,
one per thing the plugin provides; the registration's ``factory`` builds the object on demand, so listing
plugins never pays for building them. What each kind's factory builds, the interface the core calls, is declared in
:mod:`gaitbench.contracts`.

Plugins are found through the ``gaitbench`` entry-point group (built-in plugins use it too) and through
plugin directories (``--plugins-dir`` or ``GAITBENCH_PLUGINS_DIR``). Names are unique per kind: two
registrations of the same kind and name are reported as a conflict and neither is used.
"""

from __future__ import annotations

from typing import Literal, get_args

import pluggy

hookspec = pluggy.HookspecMarker("gaitbench")

Kind = Literal["experiment", "model", "transcription", "objective", "solver", "strategy", "controller", "observer",
               "disturbance", "reporter"]
"""Every plugin kind: the one list, written out so that a type checker reads it. Each kind has its hook below,
its contract in :data:`gaitbench.contracts.CONTRACTS` and its typed :meth:`gaitbench.plugins.PluginRegistry.create`
overload; the tests check that all of them name exactly these kinds."""


def hook_of(kind: str) -> str:
    """The hook whose registrations a kind holds: ``register_`` and the kind's plural."""
    return "register_" + (kind[:-1] + "ies" if kind.endswith("y") else kind + "s")


KINDS: dict[str, str] = {kind: hook_of(kind) for kind in get_args(Kind)}
"""Each plugin kind and the hook whose registrations it holds."""


@hookspec
def register_experiments():
    """Walking experiments: a robot, a terrain, an initial state and per-step timing.

    ``factory(**options)`` returns a :class:`gaitbench.model.experiment.Experiment` (the experiment contract); options
    (from a suite's ``options``/``grid``) parametrize a family of experiments, and invalid ones raise ``ValueError``.
    The built-in experiments are ``forward``, ``downward-slope``, ``upward-slope``, ``stairs`` (the thesis's chapter 5,
    no options), ``energetics`` (the §5.6 study's bipeds, with options) and ``compass-gait`` (the passive walker of
    Goswami, Thuilot and Espiau, 1996).
    """


@hookspec
def register_models():
    """Biped dynamic models.

    ``factory(robot)`` takes :class:`gaitbench.model.robot.RobotParameters` and returns a
    :class:`gaitbench.model.mechanics.BipedModel` (the model contract: mass matrix, Coriolis and gravity terms, input
    map, ground reaction, push-off and heel-strike maps, both stance cases). Built-in: ``biped-2dof`` (stance foot
    pinned, the First Phase model) and ``biped-4dof`` (stance-foot coordinates q3, q4, the Second Phase model).
    """


@hookspec
def register_transcriptions():
    """Transcriptions: turn a per-step gait problem into a finite-dimensional NLP.

    ``factory(**options)`` returns a :class:`gaitbench.contracts.Transcription`: it builds the NLP of a gait
    problem for a given number of nodes N and maps an NLP solution back to a trajectory with its own interpolant
    (for example direct collocation or discrete mechanics). Subclass
    :class:`gaitbench.problem.transcription.Transcription`, which implements the contract given ``discretize``.
    """


@hookspec
def register_objectives():
    """Objectives: what a step costs, the NLP's running and event costs and the COT verification recomputes.

    ``factory(**options)`` returns a :class:`gaitbench.problem.objective.Objective` (the objective contract: a
    frozen dataclass, since built NLPs are cached under it): its charged powers and smooth rate, in role order,
    serve the NLP and the fine-grid check alike. Built-in: ``net-power`` (the thesis's cost, the default),
    ``actuator-work`` and ``torque-squared``.
    """


@hookspec
def register_solvers():
    """NLP solvers.

    ``factory(**options)`` returns a :class:`gaitbench.contracts.Solver`: ``solve(nlp, parameters, initial_guess)``
    returns the shared solver result (status, objective, constraint violation, iterations, timings). A failure is
    reported as a status with a message, never raised.
    """


@hookspec
def register_strategies():
    """Gait-generation strategies: how the per-step problems of a walk are posed and combined.

    ``factory(**options)`` returns a :class:`gaitbench.contracts.Strategy`: given an experiment, a transcription
    and a solver, it produces the walk's trajectory step by step (for example one-phase or decrease-and-conquer).
    """


@hookspec
def register_controllers():
    """Tracking controllers for closed-loop simulation of a generated gait.

    ``factory(model, reference, **options)`` returns a :class:`gaitbench.contracts.Controller`, a control law mapping
    (time, state estimate, step) to joint torques and the push-off impulse (for example computed torque or partial
    feedback linearization).
    """


@hookspec
def register_observers():
    """State and disturbance observers used by tracking controllers.

    ``factory(model, **options)`` returns a :class:`gaitbench.contracts.Observer`, which estimates velocities (and
    disturbances) from measured positions and applied torques, and can be reset at impacts.
    """


@hookspec
def register_disturbances():
    """Disturbances acting on the robot during closed-loop simulation.

    ``factory(experiment, **options)`` returns a :class:`gaitbench.contracts.Disturbance`, giving generalized
    forces from (time, state, step) and the impulse acting with push-off, for example joint friction or an
    external push.
    """


@hookspec
def register_reporters():
    """Report writers.

    ``factory(**options)`` returns a :class:`gaitbench.contracts.Reporter`, which renders stored benchmark results
    into files (HTML, CSV) in an output directory.
    """
