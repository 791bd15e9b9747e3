"""The thesis's published chapter 5 numbers, typed in once, as data, with the section and figures they come from.

These are the only typed-in results of the reports: everything else is computed from the store. Source: the results
of the four experiments, thesis §5.2–5.5 (minimum ACOT and savings with Figs 5.2–5.5, 5.15–5.18, 5.28–5.31,
5.41–5.44; tracking with the figures after them).
The thesis's ACOT of Decrease & Conquer is the claim of its synthesized node-wise patchwork, which in general
violates the dynamics (docs/deviations.md, docs/model.md §7): gaitbench reports that claim and the verified figure.
"""

from __future__ import annotations

EXPERIMENTS = ("forward", "downward-slope", "upward-slope", "stairs")
"""The gaitbench experiment names of the thesis's four experiments (§5.2–5.5)."""

METHODS = ("OP-DM", "OP-DC", "SNOPT", "D&C-DM", "D&C-DC")
"""The thesis's five methods (§5.1)."""

REFERENCE_METHOD = "SNOPT"
"""The thesis's commercial reference solver; gaitbench suites label their stand-in ``reference`` (docs/model.md §10)."""

# experiment -> method -> (minimum ACOT, N at which it is first reached); the thesis section per experiment.
MINIMUM_ACOT: dict[str, dict[str, tuple[float, int]]] = {
    "forward": {"OP-DM": (0.3698, 140), "OP-DC": (0.3615, 140), "SNOPT": (0.1875, 180),
                "D&C-DM": (0.0814, 100), "D&C-DC": (0.0695, 90)},
    "downward-slope": {"OP-DM": (0.1922, 160), "OP-DC": (0.1734, 140), "SNOPT": (0.1024, 170),
                       "D&C-DM": (0.0762, 90), "D&C-DC": (0.0532, 90)},
    "upward-slope": {"OP-DM": (0.142, 180), "OP-DC": (0.1258, 140), "SNOPT": (0.1141, 190),
                     "D&C-DM": (0.081, 100), "D&C-DC": (0.0561, 90)},
    "stairs": {"OP-DM": (0.1484, 180), "OP-DC": (0.1285, 140), "SNOPT": (0.099, 200),
               "D&C-DM": (0.0632, 110), "D&C-DC": (0.039, 110)},
}
MINIMUM_ACOT_SOURCES = {"forward": "§5.2, Fig. 5.2", "downward-slope": "§5.3, Fig. 5.15",
                        "upward-slope": "§5.4, Fig. 5.28", "stairs": "§5.5, Fig. 5.41"}

# experiment -> (D&C method, baseline) -> ((min %, N), (max %, N)): the quoted range of the savings over N.
SAVINGS: dict[str, dict[tuple[str, str], tuple[tuple[float, int], tuple[float, int]]]] = {
    "forward": {("D&C-DM", "OP-DM"): ((15.74, 20), (81.78, 100)), ("D&C-DC", "OP-DC"): ((12.24, 20), (85.41, 90)),
                ("D&C-DM", "SNOPT"): ((7.99, 20), (80.31, 100)), ("D&C-DC", "SNOPT"): ((8.4, 20), (84.26, 90))},
    "downward-slope": {("D&C-DM", "OP-DM"): ((17.58, 10), (87.24, 90)),
                       ("D&C-DC", "OP-DC"): ((17.26, 10), (90.55, 90)),
                       ("D&C-DM", "SNOPT"): ((7.77, 10), (85.15, 90)),
                       ("D&C-DC", "SNOPT"): ((10.68, 10), (89.63, 90))},
    "upward-slope": {("D&C-DM", "OP-DM"): ((10.72, 10), (87.19, 100)),
                     ("D&C-DC", "OP-DC"): ((12.7, 10), (89.73, 100)),
                     ("D&C-DM", "SNOPT"): ((3.5, 10), (83.0, 100)),
                     ("D&C-DC", "SNOPT"): ((11.14, 10), (88.23, 100))},
    "stairs": {("D&C-DM", "OP-DM"): ((10.29, 20), (84.21, 110)), ("D&C-DC", "OP-DC"): ((13.77, 10), (89.96, 110)),
               ("D&C-DM", "SNOPT"): ((4.58, 10), (82.26, 110)), ("D&C-DC", "SNOPT"): ((10.0, 30), (89.05, 110))},
}
SAVINGS_SOURCES = {"forward": "§5.2, Figs. 5.4–5.5", "downward-slope": "§5.3, Figs. 5.17–5.18",
                   "upward-slope": "§5.4, Figs. 5.30–5.31", "stairs": "§5.5, Figs. 5.43–5.44"}

# experiment -> (N used for the plots, position error, velocity-estimation error, ACOT increase in %).
TRACKING: dict[str, tuple[int, str, str, float]] = {
    "forward": (100, "≈1e-4", "≈1e-4", 0.5),
    "downward-slope": (90, "≈1e-4", "≈1e-4", 0.6),
    "upward-slope": (100, "≈1e-4", "≈1e-4", 0.7),
    "stairs": (110, "≈1e-4", "≈1e-3–1e-4", 1.2),
}
TRACKING_SOURCES = {"forward": "§5.2, Figs. 5.6–5.14", "downward-slope": "§5.3, Figs. 5.19–5.27",
                    "upward-slope": "§5.4, Figs. 5.32–5.40", "stairs": "§5.5, Figs. 5.45–5.53"}

FIGURES: dict[str, dict[str, str]] = {
    "forward": {"acot": "5.2", "cot_bounds": "5.3", "savings_op": "5.4", "savings_reference": "5.5",
                "angles": "5.6", "velocities": "5.9", "torques": "5.12", "ground_reaction": "5.13",
                "push_off": "5.14"},
    "downward-slope": {"acot": "5.15", "cot_bounds": "5.16", "savings_op": "5.17", "savings_reference": "5.18",
                       "angles": "5.19", "velocities": "5.22", "torques": "5.25", "ground_reaction": "5.26",
                       "push_off": "5.27"},
    "upward-slope": {"acot": "5.28", "cot_bounds": "5.29", "savings_op": "5.30", "savings_reference": "5.31",
                     "angles": "5.32", "velocities": "5.35", "torques": "5.38", "ground_reaction": "5.39",
                     "push_off": "5.40"},
    "stairs": {"acot": "5.41", "cot_bounds": "5.42", "savings_op": "5.43", "savings_reference": "5.44",
               "angles": "5.45", "velocities": "5.48", "torques": "5.51", "ground_reaction": "5.52",
               "push_off": "5.53"},
}
"""The thesis figure each regenerated figure corresponds to."""


def figure(experiment: str, role: str) -> str | None:
    """``"Fig 5.2"`` for the thesis's counterpart of a figure, or None for experiments the thesis does not have."""
    number = FIGURES.get(experiment, {}).get(role)
    return f"Fig {number}" if number else None
