"""Dolan–Moré performance profiles: ratios to the best solver per problem, failures at infinity, shares within τ."""

import math

import numpy as np
import pytest

from gaitbench.reports.profiles import largest_ratio, performance_ratios, profile, profile_svg

# Three solvers, four problems; None is a failure. Best per problem: 1, 2, 3, 1.
TIMES = {"a": [1.0, 2.0, None, 4.0], "b": [2.0, 2.0, 3.0, math.nan], "c": [4.0, math.inf, 6.0, 1.0]}


def test_ratios_are_to_the_best_solver_of_each_problem_with_failures_at_infinity():
    ratios = performance_ratios(TIMES)
    assert ratios["a"].tolist() == [1.0, 1.0, math.inf, 4.0]
    assert ratios["b"].tolist() == [2.0, 1.0, 1.0, math.inf]
    assert ratios["c"].tolist() == [4.0, math.inf, 2.0, 1.0]
    assert largest_ratio(ratios) == 4.0


def test_profiles_count_the_share_of_problems_within_tau_of_the_best():
    ratios = performance_ratios(TIMES)
    taus = [1.0, 1.5, 2.0, 4.0, 1e9]
    assert profile(ratios["a"], taus).tolist() == [0.5, 0.5, 0.5, 0.75, 0.75]
    assert profile(ratios["b"], taus).tolist() == [0.5, 0.5, 0.75, 0.75, 0.75]
    assert profile(ratios["c"], taus).tolist() == [0.25, 0.25, 0.5, 0.75, 0.75]


def test_a_problem_no_solver_solved_stays_in_the_count():
    ratios = performance_ratios({"a": [1.0, None], "b": [3.0, None]})
    assert profile(ratios["a"], [1.0, 10.0]).tolist() == [0.5, 0.5]
    assert profile(ratios["b"], [2.0, 3.0]).tolist() == [0.0, 0.5]


def test_bad_tables_are_refused_with_the_solver_named():
    with pytest.raises(ValueError, match="one measure per problem"):
        performance_ratios({"a": [1.0, 2.0], "b": [1.0]})
    with pytest.raises(ValueError, match="solver 'b', problem 1"):
        performance_ratios({"a": [1.0, 2.0], "b": [1.0, 0.0]})


def test_the_figure_has_a_curve_per_solver_and_panel_on_a_log2_axis():
    ratios = {f"solver {name}": values for name, values in performance_ratios(TIMES).items()}
    svg = profile_svg({"time ratio τ": ratios, "COT ratio τ": ratios})
    assert svg.startswith("<?xml")
    assert svg.count("time ratio τ") == 1 and svg.count("COT ratio τ") == 1
    assert all(svg.count(f"solver {name}") == 1 for name in TIMES)  # one legend
    assert svg.count(">2</text>") == 2 and svg.count(">4</text>") == 2  # τ ticks on each panel's log2 axis
    assert largest_ratio({"x": np.array([math.inf])}) == 1.0
