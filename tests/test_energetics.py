import math

import casadi
import numpy as np
import pytest

from gaitbench.model.energetics import (
    average_cot,
    candidate_cot,
    cost_of_transport,
    hip_energy,
    hip_power,
    simpson_weights,
    smooth_abs,
)
from gaitbench.problem.objective import NET_POWER


@pytest.mark.parametrize("n", range(3, 13))
def test_simpson_weights_are_exact_for_cubics(n):
    t0, t1 = -0.4, 1.3
    t = np.linspace(t0, t1, n)
    h = (t1 - t0) / (n - 1)
    poly = np.polynomial.Polynomial([0.7, -1.1, 2.3, -3.7])
    exact = poly.integ()(t1) - poly.integ()(t0)
    assert h * simpson_weights(n) @ poly(t) == pytest.approx(exact, rel=1e-12, abs=1e-12)


def test_simpson_weights_have_the_expected_pattern():
    np.testing.assert_allclose(simpson_weights(2), [0.5, 0.5])
    np.testing.assert_allclose(simpson_weights(5), np.array([1, 4, 2, 4, 1]) / 3)
    np.testing.assert_allclose(simpson_weights(4), np.array([3, 9, 9, 3]) / 8)
    np.testing.assert_allclose(simpson_weights(6), [1 / 3, 4 / 3, 1 / 3 + 3 / 8, 9 / 8, 9 / 8, 3 / 8])
    for n in range(2, 30):
        assert simpson_weights(n).sum() == pytest.approx(n - 1)


@pytest.mark.parametrize("bad", [1, 0, -3, 2.5, True])
def test_simpson_weights_reject_too_few_or_non_integer_nodes(bad):
    with pytest.raises(ValueError):
        simpson_weights(bad)


@pytest.mark.parametrize("parity", [0, 1])
def test_simpson_converges_at_fourth_order_for_sin(parity):
    errors = []
    for n in (10 + parity, 20 + parity, 40 + parity):
        t = np.linspace(0.0, math.pi, n)
        errors.append(abs((t[1] - t[0]) * simpson_weights(n) @ np.sin(t) - 2.0))
    assert errors[-1] < 1e-6
    assert errors[0] / errors[-1] > 50  # ~ 2^4 per halving of h


def test_smooth_abs_bounds_the_absolute_value_within_eps():
    x = np.linspace(-3, 3, 601)
    for eps in (0.1, 1.0):
        s = smooth_abs(x, eps)
        assert np.all(s >= np.abs(x))
        assert np.all(s - np.abs(x) <= eps + 1e-15)
    assert smooth_abs(0.0) == pytest.approx(0.1)
    y = casadi.SX.sym("y")
    assert float(casadi.Function("f", [y], [smooth_abs(y)])(-2.0)) == pytest.approx(math.sqrt(4.01))


def test_hip_energy_integrates_the_absolute_power():
    t = np.linspace(0.0, 2 * math.pi, 41)
    power = hip_power(np.cos(t), 0.0, 1.0, 0.0)  # tau1 = 1 Nm, dq1 = cos t
    assert hip_energy(t, power) == pytest.approx(4.0, rel=1e-4)  # ∫|cos| over a period
    assert hip_energy(t[1] - t[0], power) == pytest.approx(hip_energy(t, power))
    assert hip_energy(t, power, smooth=0.1) > hip_energy(t, power)


def test_hip_energy_accepts_casadi_power():
    p = casadi.SX.sym("p", 5)
    energy = casadi.Function("e", [p], [hip_energy(0.25, p)])
    values = np.array([1.0, -2.0, 0.5, -0.5, 3.0])
    assert float(energy(values)) == pytest.approx(hip_energy(0.25, values))
    smooth = casadi.Function("s", [p], [hip_energy(0.25, p, smooth=0.1)])
    assert float(smooth(values)) == pytest.approx(hip_energy(0.25, values, smooth=0.1))


def test_hip_energy_rejects_non_uniform_times():
    with pytest.raises(ValueError, match="uniformly spaced"):
        hip_energy([0.0, 0.1, 0.3], np.ones(3))


def test_cost_of_transport_of_a_hand_computed_case():
    # 80 kg robot, 1.2 m chord: 94.176 J is exactly 0.1 of M g D = 80 * 9.81 * 1.2 = 941.76 J
    assert cost_of_transport(94.176, 80.0, 1.2) == pytest.approx(0.1)
    assert cost_of_transport(10.0, 1.0, 1.0, g=10.0) == pytest.approx(1.0)
    assert average_cot([0.1, 0.2, 0.6]) == pytest.approx(0.3)
    with pytest.raises(ValueError):
        cost_of_transport(1.0, 0.0, 1.0)
    with pytest.raises(ValueError):
        average_cot([])


def test_point_costs_add_the_push_off_energy_at_the_last_node():
    dq = np.array([[1.0, -1.0], [2.0, 0.5], [-1.0, 1.0]])
    tau = np.array([[3.0, 1.0], [-1.0, 2.0], [2.0, -1.0]])
    pcot = NET_POWER.point_costs(dq, tau, 5.0, stance=1, robot=np.zeros(8))
    np.testing.assert_allclose(pcot, [2.0, 1.0, 3.0 + 5.0])
    assert candidate_cot(pcot, 10.0, 2.0, g=10.0) == pytest.approx(11.0 / 200.0)
