"""Closed-loop tracking (issue 8): controllers, observers and disturbances on a solved forward walk.

One small gait (forward, Hermite–Simpson + IPOPT, N = 15, two steps) is solved once for the module; docs/tracking.md
quotes what the loops measure on it.
"""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gaitbench.cli.main import main
from gaitbench.contracts import WalkProblem
from gaitbench.control.closed_loop import track
from gaitbench.control.falls import FallCriteria
from gaitbench.control.reference import Reference
from gaitbench.control.results import SERIES_KEYS
from gaitbench.control.tracking import track_walk
from gaitbench.model.mechanics import BipedModel
from gaitbench.plugins import UnknownPluginError, load_registry
from gaitbench.solve.one_phase import OnePhase
from gaitbench.solve.walk_file import WalkFileError, load_walk, write_walk
from gaitbench_plugins.solvers.ipopt import Ipopt
from gaitbench_plugins.transcriptions.hermite_simpson import HermiteSimpson

REGISTRY = load_registry()


@pytest.fixture(scope="module")
def walk():
    experiment = REGISTRY.create("experiment", "forward")
    result = OnePhase().solve(WalkProblem(experiment, HermiteSimpson(), Ipopt(), 15, steps=2))
    assert result.complete, result.failure
    return result


@pytest.fixture(scope="module")
def reference(walk):
    return Reference.from_walk(walk, REGISTRY.create("experiment", "forward"))


@pytest.fixture(scope="module")
def saved(walk, tmp_path_factory):
    return write_walk(walk, tmp_path_factory.mktemp("walk") / "forward.json")


def run(reference, controller="thesis", observer="thesis", disturbance="friction", *, controller_options=None,
        disturbance_object=None, **kwargs):
    model = reference.model
    return track(
        reference,
        REGISTRY.create("controller", controller, model, reference, **(controller_options or {})),
        REGISTRY.create("observer", observer, model),
        disturbance_object or REGISTRY.create("disturbance", disturbance, reference.experiment),
        **kwargs,
    )


def test_every_plugin_is_registered_and_builds(reference):
    assert REGISTRY.names("controller") == ["computed-torque", "pd", "pfl", "thesis"]
    assert REGISTRY.names("observer") == ["disturbance", "ideal", "thesis", "velocity"]
    assert REGISTRY.names("disturbance") == ["friction", "none", "push"]
    for name in REGISTRY.names("controller"):
        assert hasattr(REGISTRY.create("controller", name, reference.model, reference), "torque")
    for name in REGISTRY.names("observer"):
        assert hasattr(REGISTRY.create("observer", name, reference.model), "estimate")
    for name in REGISTRY.names("disturbance"):
        assert hasattr(REGISTRY.create("disturbance", name, reference.experiment), "force")
    with pytest.raises(ValueError, match="gains must be positive"):
        REGISTRY.create("controller", "thesis", reference.model, reference, kp=-1)
    with pytest.raises(ValueError, match="point"):
        REGISTRY.create("disturbance", "push", reference.experiment, point="knee")


@pytest.mark.parametrize(("controller", "steps"), [("thesis", 2), ("computed-torque", 1)])
def test_exact_model_with_ideal_observer_tracks_to_integrator_tolerance(reference, controller, steps):
    """Same model, true velocities, no disturbance: the robot follows the reference to the integrator's accuracy
    (rtol = atol = 1e-10), across push-off and heel strike, and pushes off with the planned impulse."""
    result = run(reference, controller, "ideal", "none", steps=steps)
    data = result.as_dict()
    assert not data["fell"] and data["steps_tracked"] == steps
    assert data["max_position_error"] < 1e-8
    assert data["max_velocity_tracking_error"] < 1e-6
    for step in data["steps"]:
        assert step["push_off_impulse"] == pytest.approx(step["push_off_impulse_reference"], rel=1e-6, abs=1e-9)
        # Perfect tracking costs what the exact model's inverse dynamics along the reference cost.
        assert step["cot_tracked"] == pytest.approx(step["cot_ideal"], rel=1e-2)


def test_an_integration_segment_reads_the_reference_on_its_own_interval_up_to_and_at_its_end(reference):
    """At a node the C¹ reference's acceleration jumps: a segment ending there sees its own interval's, the
    left-hand limit, so that its right-hand side is smooth up to its end."""
    step = reference.steps[0]
    node = step.times[3]
    later = step.desired(node)
    step.piece = 2
    try:
        own = step.desired(node)
    finally:
        step.piece = None
    np.testing.assert_allclose(own[0], later[0], atol=1e-12)
    np.testing.assert_allclose(own[1], later[1], atol=1e-9)
    assert np.max(np.abs(own[2] - later[2])) > 1e-3
    np.testing.assert_allclose(own[2], step.desired(node - 1e-9)[2], rtol=1e-5)
    run(reference, "thesis", "ideal", "none", steps=1)
    assert step.piece is None  # the loop leaves the reference as it found it


def test_a_downhill_walk_tracked_exactly_does_not_fall():
    """The downward slope's first step takes the stance leg to −1.9 rad, beyond the thesis's printed box and with
    the hip below the stance foot's level: tracked exactly, the robot must not count as fallen (the walk was solved
    in the physical windows; the hip's height is measured from the step's chord)."""
    experiment = REGISTRY.create("experiment", "downward-slope")
    walk = OnePhase().solve(WalkProblem(experiment, HermiteSimpson(), Ipopt(), 12, steps=1))
    assert walk.complete, walk.failure
    downhill = Reference.from_walk(walk, experiment)
    assert min(downhill.step(1).q_nodes[:, 0]) < experiment.limits.angle_bounds[0]  # beyond the printed box
    data = run(downhill, "thesis", "ideal", "none", steps=1).as_dict()
    assert not data["fell"], data.get("fall")
    assert data["max_position_error"] < 1e-6


def test_a_walk_solved_under_another_cost_is_compared_with_its_plan_in_the_tracked_cost(reference):
    """Tracking measures net hip power plus the push-off's energy; a walk solved under actuator-work (which charges
    more for the same motion: 0.0198 against 0.0127 here) is compared with its plan in that same measure, so exact
    tracking shows the few percent the exact model's torques differ from the transcription's (as on a net-power
    walk), not a 35 % saving made of two cost definitions."""
    from gaitbench_plugins.objectives.energy_costs import ActuatorWork

    experiment = REGISTRY.create("experiment", "forward")
    walk = OnePhase().solve(WalkProblem(experiment, HermiteSimpson(), Ipopt(), 12, steps=1, objective=ActuatorWork()))
    assert walk.complete, walk.failure
    worked = Reference.from_walk(walk, experiment)
    assert worked.step(1).cot < walk.steps[0].verification.cot  # the same motion, measured as tracking does
    data = run(worked, "thesis", "ideal", "none", steps=1).as_dict()
    assert not data["fell"] and data["steps"][0]["cot_tracked"] == pytest.approx(data["steps"][0]["cot_ideal"],
                                                                               rel=1e-2)
    assert abs(data["acot_increase_percent"]) < 5.0


def test_thesis_closed_form_contact_force_breaks_the_linearization(reference):
    """PFL with the thesis's (3.39) contact force leaves q̈_a = M11⁻¹ M_a v_a: the swing foot misses the ground."""
    result = run(reference, "pfl", "ideal", "none", controller_options={"contact_force": "thesis"}, steps=1)
    assert result.as_dict()["max_position_error"] > 1e-2
    assert result.fell and "missed the ground" in result.fall.reason


def test_friction_with_observers_stays_bounded_and_costs_energy(reference):
    """Friction with the thesis's observers: errors stay small, well below the same loop without the disturbance
    estimate (docs/tracking.md, "Measured results"), and the ACOT increase is reported."""
    observed = run(reference, "thesis", "thesis", "friction").as_dict()
    assert not observed["fell"] and observed["steps_tracked"] == 2
    assert observed["max_position_error"] < 1e-3
    assert observed["max_velocity_error"] < 2e-2
    assert observed["acot_tracked"] > observed["acot_reference"]
    assert observed["acot_increase_percent"] == pytest.approx(
        100 * (observed["acot_tracked"] / observed["acot_reference"] - 1))
    unestimated = run(reference, "thesis", "ideal", "friction", steps=1).as_dict()
    assert unestimated["max_position_error"] > 5 * observed["steps"][0]["max_position_error"]["leg2"]


class ConstantDisturbance:
    """d = (4, −6) N·m on the leg angles, constant over the walk (the thesis's Assumption 1, ḋ = 0)."""

    value = np.array([4.0, -6.0])

    def force(self, t, q, dq, step):
        return np.r_[self.value, np.zeros(len(q) - 2)]

    def impulse(self, q, dq, step):
        return np.zeros(len(q))


def test_observers_converge_on_a_constant_disturbance_and_survive_the_impact(reference):
    """The working-form observers learn a constant disturbance and keep it through push-off and heel strike
    (t = 0.7343 s), where they are reset consistently."""
    result = run(reference, "thesis", "thesis", disturbance_object=ConstantDisturbance())
    series = result.series
    error = np.abs(series["disturbance_estimated"] - series["disturbance"]).max(axis=1)
    velocity = np.abs(series["dq"] - series["dq_estimated"]).max(axis=1)
    t = series["t"]
    assert error[0] == pytest.approx(6.0)  # starts from d̂ = 0
    assert error[t >= 0.3].max() < 2e-3
    assert error[t >= 0.5].max() < 1e-5  # including the second step, after the impact
    assert velocity[t >= 0.3].max() < 1e-6
    assert not result.fell


def test_zero_order_hold_holds_the_torque_and_costs_accuracy(reference):
    """Sampled, the exact loop loses accuracy as the rate falls (500 Hz against 100 Hz), and holds the torque."""
    fast = run(reference, "thesis", "ideal", "none", sample_rate=500.0, steps=1)
    slow = run(reference, "thesis", "ideal", "none", sample_rate=100.0, steps=1)
    fast_error, slow_error = fast.as_dict()["max_position_error"], slow.as_dict()["max_position_error"]
    assert 1e-8 < fast_error < slow_error < 1e-3
    t, tau = slow.series["t"], slow.series["tau"]
    period = np.floor(t / 1e-2 + 1e-9)
    inside = (period[1:] == period[:-1]) & (t[1:] - period[1:] * 1e-2 > 1e-9)  # same hold interval
    assert np.array_equal(tau[1:][inside], tau[:-1][inside])
    assert not np.array_equal(tau[1:], tau[:-1])


def test_a_push_on_an_open_loop_robot_is_detected_as_a_fall(reference):
    """PD with negligible gains is open loop; a 1500 N backward push at the hip makes it fall within the step."""
    push = REGISTRY.create("disturbance", "push", reference.experiment, force=1500.0, angle=np.pi, time=0.1,
                           duration=0.2)
    result = run(reference, "pd", "ideal", controller_options={"kp": 1e-3, "kd": 1e-3}, disturbance_object=push)
    fall = result.as_dict()["fall"]
    assert result.fell and fall["step"] == 1
    assert 0.1 < fall["time"] < reference.steps[0].info.duration
    assert fall["reason"] in ("foot through the ground", "hip too low", "leg angle out of range")
    assert result.as_dict()["acot_tracked"] is None  # no step completed
    with pytest.raises(ValueError, match="hip_fraction"):
        FallCriteria(hip_fraction=1.5)


def test_a_fall_before_a_segment_s_first_recorded_time_is_recorded_as_a_fall(reference):
    """A 10 MN push just after a node topples the open-loop robot before the segment's first recorded sample:
    the integrator then returns its states as an empty list, which once raised instead of recording the fall."""
    node = reference.steps[0].times[3]
    push = REGISTRY.create("disturbance", "push", reference.experiment, force=1e7, angle=np.pi, time=node + 1e-5,
                           duration=1e-3)
    result = run(reference, "pd", "ideal", controller_options={"kp": 1e-3, "kd": 1e-3}, disturbance_object=push)
    assert result.fell and node < result.as_dict()["fall"]["time"] < node + reference.steps[0].info.time_step


def test_stored_walk_gives_the_same_reference_and_a_complete_record(walk, reference, saved, tmp_path):
    """The NPZ rebuilt through the transcription's interpolant is the in-memory reference; the result saves JSON and
    the time series a report plots."""
    loaded, _ = load_walk(saved, REGISTRY)
    rebuilt = Reference.from_walk(loaded, reference.experiment)
    for original, copy in zip(reference.steps, rebuilt.steps, strict=True):
        for t in np.linspace(0, original.info.duration, 37):
            for a, b in zip(original.desired(t), copy.desired(t), strict=True):
                np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    result = track_walk(saved, "thesis", "ideal", "none", options={"steps": 1}, registry=REGISTRY)
    path = result.save(tmp_path / "track.json")
    data = json.loads(path.read_text())
    for key in ("max_position_error", "max_velocity_error", "acot_reference", "acot_tracked",
                "acot_increase_percent", "fell", "fall", "steps"):
        assert key in data
    assert data["walk"]["source"] == str(saved)
    series = np.load(tmp_path / data["series"])
    assert set(series.files) == set(SERIES_KEYS)
    assert series["q"].shape == series["q_desired"].shape == (len(series["t"]), 2)


def test_bad_inputs_name_the_file_and_the_fix(saved, tmp_path):
    with pytest.raises(WalkFileError, match="no such result file.*gaitbench solve"):
        load_walk(tmp_path / "missing.json", REGISTRY)
    orphan = tmp_path / "orphan.json"
    orphan.write_text(saved.read_text())
    with pytest.raises(WalkFileError, match=r"orphan\.json.*forward\.npz is missing"):
        load_walk(orphan, REGISTRY)
    (tmp_path / "broken.json").write_text('{"experiment": "forward"}')
    with pytest.raises(WalkFileError, match="broken.json: not a walk result, missing"):
        load_walk(tmp_path / "broken.json", REGISTRY)
    with pytest.raises(UnknownPluginError, match="unknown controller 'nope'"):
        track_walk(saved, controller="nope", registry=REGISTRY)
    with pytest.raises(ValueError, match="unknown option 'sampling'; allowed: controller, observer"):
        track_walk(saved, options={"sampling": 10}, registry=REGISTRY)
    with pytest.raises(ValueError, match=r"controller\.kpp: controller 'thesis': unknown option 'kpp' \(did you "
                                         r"mean 'kp'\?\)"):
        track_walk(saved, options={"controller": {"kpp": 10}}, registry=REGISTRY)


def test_track_command(saved, tmp_path):
    runner = CliRunner()
    out = tmp_path / "track.json"
    result = runner.invoke(main, ["track", str(saved), "--observer", "ideal", "--disturbance", "none", "--steps", "1",
                                  "-c", "kp=400", "-c", "kv=40", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "ACOT tracked" in result.output
    data = json.loads(out.read_text())
    assert data["configuration"]["controller"] == {"name": "thesis", "options": {"kp": 400, "kv": 40}}
    assert data["fell"] is False
    missing = runner.invoke(main, ["track", str(tmp_path / "none.json")])
    assert missing.exit_code == 2 and "no such result file" in missing.output
    unknown = runner.invoke(main, ["track", str(saved), "--observer", "nope"])
    assert unknown.exit_code == 2 and "unknown observer 'nope'" in unknown.output
    beyond = runner.invoke(main, ["track", str(saved), "--steps", "5"])  # it tracked the walk's 2 without a word
    assert beyond.exit_code == 2 and "has 2 steps" in beyond.output
    typo = runner.invoke(main, ["track", str(saved), "-c", "kpp=400"])
    assert typo.exit_code == 2 and "Traceback" not in typo.output
    assert ("'-c' / '--controller-option': controller 'thesis', option kpp: unknown option 'kpp' (did you mean "
            "'kp'?)") in " ".join(typo.stderr.split())


def test_a_decrease_and_conquer_walk_is_tracked_along_its_verified_trajectory(tmp_path):
    """Tracking follows the polished trajectory and compares with the verified ACOT, in memory and from the saved
    walk; without polish, the complete Second Phase solution each step reports."""
    from gaitbench_plugins.strategies.decrease_and_conquer import DecreaseAndConquer

    experiment = REGISTRY.create("experiment", "forward")
    problem = WalkProblem(experiment, HermiteSimpson(), Ipopt(), 8, steps=1)
    walk = DecreaseAndConquer().solve(problem)
    assert walk.complete, walk.failure
    verified, claimed = walk.strategy_details["verified_acot"], walk.strategy_details["claimed_acot"]
    assert verified != claimed  # the patchwork's claim is not the cost of the motion tracked
    saved = write_walk(walk, tmp_path / "dc.json")
    for source in (walk, saved):
        result = track_walk(source, "thesis", "ideal", "none", registry=REGISTRY)
        assert result.walk["trajectory"] == "polished"
        assert result.acot_reference == pytest.approx(verified, rel=1e-9)
    reference = Reference.from_walk(walk, experiment)
    np.testing.assert_array_equal(reference.steps[0].q_nodes, walk.steps[0].polished.trajectory.q)

    unpolished = DecreaseAndConquer(polish=False).solve(problem)
    result = track_walk(unpolished, "thesis", "ideal", "none", registry=REGISTRY)
    assert result.walk["trajectory"] == "polished"
    assert result.acot_reference == pytest.approx(unpolished.acot, rel=1e-9)


def test_the_disturbance_observers_estimate_is_kept_across_an_impact():
    """Its velocity is the sensor's: reset with the measured post-impact velocity, its estimate d̂ = p − Φ q̇ is the
    pre-impact d̂ exactly, whatever the model-mapped velocity estimate (which leaves out friction's impulse) says."""
    from gaitbench_plugins.control.observers import DisturbanceObserver

    model = BipedModel(REGISTRY.create("experiment", "forward").robot, 4)
    observer = DisturbanceObserver(model)
    q, dq_measured = np.array([0.2, -0.3, 0.0, 0.0]), np.array([-1.1, 0.4, 0.0, 0.0])
    mapped, d_before = np.array([-1.0, 0.5]), np.array([7.0, -9.0])
    state = observer.reset(q, dq_measured, mapped, d_before, None)
    _, d_after = observer.estimate(state, q, dq_measured)
    assert d_after == pytest.approx(d_before)


def test_a_free_reference_has_no_percentage_increase():
    """A passive gait's reference costs 0: the tracked cost is reported, the increase as a percentage is not."""
    from dataclasses import replace as with_

    from gaitbench.control.results import StepTracking, TrackingResult

    zeros = np.zeros(2)
    step = StepTracking(1, 1, True, zeros, zeros, zeros, zeros, zeros, 0.0, 0.0, 0.0, 0.0, 0.0, cot_reference=0.0,
                        cot_tracked=0.01, cot_ideal=0.0)
    free = TrackingResult(walk={}, configuration={}, steps=[step], series={})
    assert free.acot_tracked == pytest.approx(0.01) and free.acot_increase_percent is None
    paid = TrackingResult(walk={}, configuration={}, steps=[with_(step, cot_reference=0.008)], series={})
    assert paid.acot_increase_percent == pytest.approx(25.0)


def test_a_resisting_impulse_at_most_stops_the_velocity_it_resists():
    """Friction's push-off impulse, evaluated at the post-push-off velocity, would reverse a slow foot in full: it is
    scaled to the part that brings that velocity to rest. An impulse too weak to reverse anything, or one along the
    motion, is applied in full."""
    from gaitbench.control.closed_loop import resisted_velocities

    dq = np.array([0.5, 0.0, 0.1, 0.01])
    change = np.array([0.01, 0.0, 0.02, 0.05])
    impulse = np.array([0.0, 0.0, 1.0, 1.0])
    after = resisted_velocities(dq, change, impulse)
    assert after[3] == pytest.approx(0.0, abs=1e-15)
    assert after[2] == pytest.approx(0.1 - 0.2 * 0.02)
    assert np.all(after[2:] * dq[2:] >= 0)
    weak = np.array([0.0, 0.0, 0.02, 0.005])
    np.testing.assert_array_equal(resisted_velocities(dq, weak, impulse), dq - weak)
    assisting = np.array([0.0, 0.0, -1.0, -1.0])
    np.testing.assert_array_equal(resisted_velocities(dq, -change, assisting), dq + change)
