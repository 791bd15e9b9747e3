"""Mutation testing of the code behind the reported figures: would the tests catch a plausible mistake?

Run:    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/mutation.py [--full] [--only NAME ...] [--list]

Each mutant of :data:`MUTANTS` is one hand-made, plausible mistake in the verification, cost/objective, walk or
quadrature code: a file, the exact text it replaces (which must occur there once) and its replacement. The files of
the repository (tracked, and new ones git does not ignore) are copied once to a temporary directory (the working
tree is never changed); each mutant is applied to that copy, the chosen tests run on it (``pytest -x``, stopping
at the first failure), and the file is put back. A mutant is *killed* when the tests fail, *survives* when they
pass, and *timed out* past :data:`TIMEOUT_S`. The tests first run on the unmutated copy, which must pass.

The tests are :data:`FAST_TESTS` by default (the test files that exercise these modules, about a minute);
``--full`` runs the default test run (``pytest`` with the project's configuration, slow tests excluded). The table
(each mutant, its status, the first test that failed, its time) and the kill rate are printed and written to
``benchmarks/results/mutation.md``, or with ``--only`` to stdout alone.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "mutation.md"
TIMEOUT_S = 900
"""A mutant whose tests run longer than this (a mistake that makes a solve crawl) is recorded as timed out."""
FAST_TESTS = (
    "tests/test_verified_figures.py",
    "tests/test_energetics.py",
    "tests/test_objectives.py",
    "tests/test_objective_agreement.py",
    "tests/test_walk.py",
    "tests/test_mechanics.py",
    "tests/test_walk_verification.py",
)
"""The tests of verification (of steps and of whole walks), objectives, quadrature, walks and the role-order
mechanics."""
LIST_CHECK = "tests/test_benchmarks.py::test_every_mutant_of_the_mutation_check_names_text_that_occurs_once_in_its_file"
"""The test that :data:`MUTANTS` follows the code: it fails on any mutated tree, so it is no test of a mutant."""


@dataclass(frozen=True)
class Mutant:
    name: str
    path: str
    original: str
    replacement: str


MUTANTS = (
    # verification (gaitbench/solve/verify.py)
    Mutant("verify: COT without the push-off energy", "gaitbench/solve/verify.py",
           "energy + objective.event_cost(push_off_energy)", "energy"),
    Mutant("verify: push-off only in 2 DOF", "gaitbench/solve/verify.py",
           "push_off_cost) if model.dof == 4 else 0.0", "push_off_cost) if model.dof == 2 else 0.0"),
    Mutant("verify: resim_error at the first node", "gaitbench/solve/verify.py",
           "resim_error=float(errors[-1])", "resim_error=float(errors[0])"),
    Mutant("verify: resim_max_error at the last node", "gaitbench/solve/verify.py",
           "resim_max_error=float(errors.max())", "resim_max_error=float(errors[-1])"),
    Mutant("verify: one-sided objective check", "gaitbench/solve/verify.py",
           "bool(abs(gap) <= OBJECTIVE_RTOL)", "bool(gap <= OBJECTIVE_RTOL)"),
    Mutant("verify: objective gap floor without 1/RTOL", "gaitbench/acceptance.py",
           "max(abs(cot), walk_cot, OBJECTIVE_ATOL / OBJECTIVE_RTOL)", "max(abs(cot), walk_cot, OBJECTIVE_ATOL)"),
    Mutant("walk verification: gap against the step's COT alone", "gaitbench/solve/walk_verification.py",
           "step_failures(check, limits, walk_cot)", "step_failures(check, limits)"),
    Mutant("walk verification: join against the state the strategy handed on", "gaitbench/solve/walk_verification.py",
           "expected = next_step_state(impact, trajectory)", "expected = motion.next_state"),
    Mutant("verify: fine grid reads controls at the nodes", "gaitbench/solve/verify.py",
           "np.clip(np.linspace(0.0, 1.0, samples_per_interval + 1), INSIDE, 1.0 - INSIDE)",
           "np.linspace(0.0, 1.0, samples_per_interval + 1)"),
    Mutant("verify: fine grid spacing off by one", "gaitbench/solve/verify.py",
           "hip_energy((end - start) / samples_per_interval, rate)",
           "hip_energy((end - start) / (samples_per_interval + 1), rate)"),
    Mutant("verify: fine grid one sample short", "gaitbench/solve/verify.py",
           "np.linspace(0.0, 1.0, samples_per_interval + 1), INSIDE",
           "np.linspace(0.0, 1.0, samples_per_interval), INSIDE"),
    Mutant("verify: push-off from the step's start state", "gaitbench/solve/verify.py",
           "np.r_[trajectory.q[-1], foot], np.r_[trajectory.dq[-1], foot]",
           "np.r_[trajectory.q[0], foot], np.r_[trajectory.dq[0], foot]"),
    Mutant("verify: re-simulation from the second node", "gaitbench/solve/verify.py",
           "q0, dq0 = trajectory.q[0], trajectory.dq[0]", "q0, dq0 = trajectory.q[1], trajectory.dq[1]"),
    # objectives (gaitbench/problem/objective.py, plugins/objectives/energy_costs.py)
    Mutant("objective: |·| removed from the charged power", "gaitbench/problem/objective.py",
           "return np.abs(power)", "return power"),
    Mutant("objective: push-off work never charged", "gaitbench/problem/objective.py",
           "return float(work) if self.signed_event else float(self.charge(work))", "return float(work)"),
    Mutant("objective: point cost's push-off at the first node", "gaitbench/problem/objective.py",
           "pcot[-1] += self.event_cost(push_off_work)", "pcot[0] += self.event_cost(push_off_work)"),
    Mutant("objective: rates and torques read in leg order for a Leg-2 stance", "gaitbench/problem/objective.py",
           "order = [0, 1] if stance == 1 else [1, 0]", "order = [0, 1]"),
    Mutant("actuator-work: hip power on the swing rate alone", "plugins/objectives/energy_costs.py",
           "hip = tau_sw * (dq_sw - dq_st)", "hip = tau_sw * dq_sw"),
    Mutant("actuator-work: ankle torque without the hip's reaction", "plugins/objectives/energy_costs.py",
           "ankle = (tau_st + tau_sw) * dq_st", "ankle = tau_st * dq_st"),
    Mutant("actuator-work: Margaria efficiencies swapped", "plugins/objectives/energy_costs.py",
           "return 1 / MARGARIA_POSITIVE_EFFICIENCY if self.margaria else 1.0",
           "return 1 / MARGARIA_NEGATIVE_EFFICIENCY if self.margaria else 1.0"),
    Mutant("actuator-work: negative work costs 1.2 J per joule", "plugins/objectives/energy_costs.py",
           "return 1 / MARGARIA_NEGATIVE_EFFICIENCY if self.margaria else 1.0",
           "return MARGARIA_NEGATIVE_EFFICIENCY if self.margaria else 1.0"),
    Mutant("torque-squared: time scale √(g/l) for √(g l)", "plugins/objectives/energy_costs.py",
           "(g * leg) ** 0.5", "(g / leg) ** 0.5"),
    # the NLP's cost (gaitbench/problem/transcription.py, step_cost.py, plugins/transcriptions/dmoc.py)
    Mutant("NLP cost: COT weight without g", "gaitbench/problem/transcription.py",
           "weight = symbols.total_mass * symbols.gravity * symbols.chord",
           "weight = symbols.total_mass * symbols.chord"),
    Mutant("NLP cost: objective COT with the torque regularization", "gaitbench/problem/transcription.py",
           "[nlp.x, symbols.vector], [energy / weight]",
           "[nlp.x, symbols.vector], [(energy + regularization) / weight]"),
    Mutant("NLP cost: node slack split signed", "gaitbench/problem/step_cost.py",
           "return _scaled(positive, positive_weight) + _scaled(negative, negative_weight)",
           "return _scaled(positive, positive_weight) - _scaled(negative, negative_weight)"),
    Mutant("NLP cost: interval slack split signed", "gaitbench/problem/step_cost.py",
           "_scaled(positive, objective.positive_weight) + _scaled(negative, objective.negative_weight)",
           "_scaled(positive, objective.positive_weight) - _scaled(negative, objective.negative_weight)"),
    Mutant("NLP cost: smoothed |P|'s weight asymmetry signed wrong", "gaitbench/problem/step_cost.py",
           "+ (positive_weight - negative_weight) / 2 * powers)",
           "- (positive_weight - negative_weight) / 2 * powers)"),
    Mutant("DMOC cost: Legendre sign at the interval start", "plugins/transcriptions/dmoc.py",
           "model.mass(q_a, robot), -d1 - h / 2 * tau)", "model.mass(q_a, robot), -d1 + h / 2 * tau)"),
    Mutant("DMOC cost: Legendre sign at the interval end", "plugins/transcriptions/dmoc.py",
           "model.mass(q_b, robot), d2 + h / 2 * tau)", "model.mass(q_b, robot), d2 - h / 2 * tau)"),
    # quadrature (gaitbench/problem/step_cost.py, gaitbench/model/energetics.py)
    Mutant("quadrature: Boole weight 12/90 -> 14/90", "gaitbench/problem/step_cost.py",
           "(32 / 90, 12 / 90, 32 / 90)", "(32 / 90, 14 / 90, 32 / 90)"),
    Mutant("quadrature: Boole end weight 7/90 -> 7/45", "gaitbench/problem/step_cost.py",
           "QuadratureRule(7 / 90,", "QuadratureRule(7 / 45,"),
    Mutant("quadrature: Boole points at thirds", "gaitbench/problem/step_cost.py",
           "(1 / 4, 1 / 2, 3 / 4)", "(1 / 3, 1 / 2, 2 / 3)"),
    Mutant("quadrature: Simpson end weight 1/6 -> 1/3", "gaitbench/problem/step_cost.py",
           "QuadratureRule(1 / 6,", "QuadratureRule(1 / 3,"),
    Mutant("quadrature: 3/8 rule over 9", "gaitbench/model/energetics.py",
           "np.array([3.0, 9.0, 9.0, 3.0]) / 8.0", "np.array([3.0, 9.0, 9.0, 3.0]) / 9.0"),
    Mutant("energetics: COT without g", "gaitbench/model/energetics.py",
           "return energy / (total_mass * g * chord)", "return energy / (total_mass * chord)"),
    # role order (gaitbench/problem/gait_problem.py)
    Mutant("roles: stance and swing masses not swapped", "gaitbench/problem/gait_problem.py",
           "vector[[0, 1]] = vector[[1, 0]]", "vector[[0, 1]] = vector[[0, 1]]"),
    Mutant("roles: stance and swing inertias not swapped", "gaitbench/problem/gait_problem.py",
           "vector[[5, 6]] = vector[[6, 5]]", "vector[[5, 6]] = vector[[5, 6]]"),
    # walks (gaitbench/walk_types.py, gaitbench/solve/walk.py, gaitbench/model/energetics.py)
    Mutant("walk: ACOT over a partial walk's solved steps", "gaitbench/walk_types.py",
           "return average_cot([step.verified.verification.cot for step in self.steps]) if self.complete else None",
           "solved = [step.verified.verification.cot for step in self.steps if step.solved]\n"
           "        return average_cot(solved) if solved else None"),
    Mutant("walk: complete without its requested steps", "gaitbench/walk_types.py",
           "return len(self.steps) == self.requested_steps and all(", "return len(self.steps) > 0 and all("),
    Mutant("walk: ACOT the median", "gaitbench/model/energetics.py",
           "return float(values.mean())", "return float(np.median(values))"),
    Mutant("walk: a polished step's verified outcome ignored", "gaitbench/walk_types.py",
           "return self.polished if self.polished is not None and self.polished.solved else self", "return self"),
    Mutant("walk: next step starts without the push-off", "gaitbench/solve/walk.py",
           "dq, _ = model.push_off(q, dq, trajectory.push_off, trajectory.stance)",
           "_ = model.push_off(q, dq, trajectory.push_off, trajectory.stance)"),
)


@dataclass
class Outcome:
    mutant: Mutant
    status: str  # killed, survived, timed out
    failed_test: str
    seconds: float


def copy_tree(destination: Path) -> None:
    """The repository's files (tracked, and new ones not ignored), as they are in the working tree, copied under
    ``destination``, with ``gaitbench_plugins`` (the package name of ``plugins/``) linked to the copy's
    ``plugins/``: on ``PYTHONPATH`` it comes before the editable install's finder, which would import the working
    tree's plugins, unmutated."""
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                            capture_output=True, check=True).stdout
    for name in filter(None, listed.decode().split("\0")):
        source = ROOT / name
        if source.is_file():
            (destination / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, destination / name)
    (destination / "gaitbench_plugins").symlink_to("plugins", target_is_directory=True)


def check_imports_the_copy(tree: Path) -> None:
    """Refuse to run when the tests would import gaitbench or its plugins from anywhere but the copy: a mutant
    there would survive whatever the tests do."""
    for package in ("gaitbench", "gaitbench_plugins"):
        found = subprocess.run([sys.executable, "-c", f"import {package}; print({package}.__path__[0])"], cwd=tree,
                               env={**_environment(), "PYTHONPATH": str(tree)}, capture_output=True, text=True)
        if not found.stdout.strip().startswith(str(tree)):
            raise SystemExit(f"Error: the tests would import {package} from {found.stdout.strip() or found.stderr}, "
                             f"not from the mutated copy {tree}")


def run_tests(tree: Path, tests: list[str]) -> tuple[str, str]:
    """(status, first failed test) of ``pytest -x`` on ``tests`` in ``tree``: passed, failed or timed out."""
    command = [sys.executable, "-m", "pytest", "-x", "-q", "-rfE", "-p", "no:cacheprovider", "--deselect", LIST_CHECK,
               *tests]  # -rfE: the summary names the failed test, whatever the configuration's -r says
    environment = {**_environment(), "PYTHONPATH": str(tree)}
    try:
        run = subprocess.run(command, cwd=tree, env=environment, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return "timed out", ""
    if run.returncode == 0:
        return "passed", ""
    found = re.search(r"^(?:FAILED|ERROR) (\S+)", run.stdout, re.MULTILINE)
    return "failed", found.group(1) if found else f"pytest exit {run.returncode}"


def _environment() -> dict[str, str]:
    import os

    return {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


def apply(tree: Path, mutant: Mutant) -> str:
    """Apply ``mutant`` to the copy; returns the file's original text (to put back)."""
    path = tree / mutant.path
    text = path.read_text()
    count = text.count(mutant.original)
    if count != 1:
        raise SystemExit(f"Error: mutant {mutant.name!r}: its text occurs {count} times in {mutant.path} (expected 1)")
    path.write_text(text.replace(mutant.original, mutant.replacement))
    return text


def run(mutants: list[Mutant], tests: list[str]) -> list[Outcome]:
    outcomes = []
    with tempfile.TemporaryDirectory(prefix="gaitbench-mutation-") as directory:
        tree = Path(directory)
        copy_tree(tree)
        check_imports_the_copy(tree)
        for mutant in mutants:  # every mutant's text must be found before anything runs
            (tree / mutant.path).write_text(apply(tree, mutant))
        status, failed = run_tests(tree, tests)
        if status != "passed":
            raise SystemExit(f"Error: the tests fail on the unmutated tree ({status}: {failed}); fix that first")
        for mutant in mutants:
            original = apply(tree, mutant)
            started = time.perf_counter()
            try:
                status, failed = run_tests(tree, tests)
            finally:
                (tree / mutant.path).write_text(original)
            verdict = {"failed": "killed", "passed": "survived"}.get(status, status)
            outcome = Outcome(mutant, verdict, failed, time.perf_counter() - started)
            print(f"{verdict:9s} {outcome.seconds:6.1f} s  {mutant.name}  {failed}", flush=True)
            outcomes.append(outcome)
    return outcomes


def table(outcomes: list[Outcome], selection: str, commit: str) -> str:
    killed = sum(outcome.status == "killed" for outcome in outcomes)
    lines = [
        "# Mutation testing",
        "",
        f"`benchmarks/mutation.py{' --full' if selection == 'full' else ''}` at commit {commit}: "
        f"{killed} of {len(outcomes)} mutants killed ({100 * killed / len(outcomes):.0f} %) by "
        + ("the default test run." if selection == "full" else "the fast selection (" + ", ".join(
            f"`{Path(test).name}`" for test in FAST_TESTS) + ")."),
        "",
        "| mutant | file | status | first failed test | time (s) |",
        "|---|---|---|---|---:|",
    ]
    for outcome in outcomes:
        test = outcome.failed_test.removeprefix("tests/")
        name = outcome.mutant.name.replace("|", "\\|")  # a table cell's own bars
        lines.append(f"| {name} | `{outcome.mutant.path}` | {outcome.status} | "
                     f"{f'`{test}`' if test else ''} | {outcome.seconds:.0f} |")
    return "\n".join(lines) + "\n"


def tested_commit() -> str:
    """The commit the tree is copied from, ``+dirty`` when the working tree differs from it (new files included)."""
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    return commit + ("+dirty" if dirty else "")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="run the default test run instead of the fast tests")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="mutants whose name contains NAME (not recorded)")
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    args = parser.parse_args(argv)
    if args.list:
        for mutant in MUTANTS:
            print(f"{mutant.name}  ({mutant.path})")
        return 0
    mutants = [mutant for mutant in MUTANTS
               if not args.only or any(part.lower() in mutant.name.lower() for part in args.only)]
    if not mutants:
        print(f"Error: no mutant's name contains any of {args.only} (see --list)", file=sys.stderr)
        return 2
    tests = [] if args.full else list(FAST_TESTS)
    commit = tested_commit()
    outcomes = run(mutants, tests)
    report = table(outcomes, "full" if args.full else "fast", commit)
    print(report)
    if not args.only:
        RESULTS.write_text(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
