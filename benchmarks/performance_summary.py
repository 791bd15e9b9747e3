"""The markdown summary of ``benchmarks/results/performance.json``: what ``performance.py`` writes to
``performance.md`` after each part it measures. Rendering only; it reads every figure from the results.
"""

from __future__ import annotations

import numpy as np


def loglog_slope(rows: list[dict], key: str, transcription: str) -> float:
    points = [(row["N"], row[key]) for row in rows if row["transcription"] == transcription and row[key] > 0]
    return float(np.polyfit(np.log([n for n, _ in points]), np.log([v for _, v in points]), 1)[0])


def summary_markdown(results: dict) -> str:
    """``performance.md`` for ``results`` (the JSON's parts by name, and the provenance of the last run)."""
    machine = results["provenance"]
    lines = ["# Performance of the core", "",
             f"Measured with `benchmarks/performance.py` on {machine['cpus']} CPUs, {machine['platform']}, Python "
             f"{machine['python']}, gaitbench {machine['gaitbench']} at {machine['git_commit'][:12]}; "
             + ", ".join(f"{name} {version}" for name, version in sorted(machine["packages"].items())
                         if name in ("casadi", "numpy", "scipy", "cyipopt-wheels")) + ".",
             "Times are wall-clock seconds of one process (OPENBLAS_NUM_THREADS=1); IPOPT through CasADi, exact "
             "Hessian, MUMPS.", ""]
    if "steps" in results:
        rows = results["steps"]
        lines += ["## One cold 4-DOF step (forward, step 1, standard guess)", "",
                  "| transcription | N | vars | transcribe (s) | IPOPT build (s) | solver memory (MB) | status | "
                  "solve (s) | iterations | ms/iteration | derivatives | rest |", "|" + "---|" * 12]
        for r in rows:
            lines.append(f"| {r['transcription']} | {r['N']} | {r['variables']} | {r['transcribe_s']:.2f} | "
                         f"{r['nlpsol_build_s']:.2f} | {r['solver_memory_mb']:.0f} | {r['status']} | "
                         f"{r['solve_s']:.2f} | {r['iterations']} | {r['per_iteration_ms']:.2f} | "
                         f"{r['derivative_per_iteration_ms']:.2f} | {r['rest_per_iteration_ms']:.2f} |")
        lines += ["", "Log–log slopes against N (1 = linear):", "",
                  "| transcription | solve time | iterations | ms/iteration | derivatives/iteration | rest/iteration "
                  "| IPOPT build | solver memory |", "|" + "---|" * 8]
        for name in dict.fromkeys(r["transcription"] for r in rows):  # in measuring order
            slopes = [loglog_slope(rows, key, name) for key in ("solve_s", "iterations", "per_iteration_ms",
                                                                 "derivative_per_iteration_ms",
                                                                 "rest_per_iteration_ms", "nlpsol_build_s",
                                                                 "solver_memory_mb")]
            lines.append(f"| {name} | " + " | ".join(f"{s:.2f}" for s in slopes) + " |")
        lines.append("")
    if "sections" in results:
        lines += ["## Sectional solves of one decrease-and-conquer step (forward, step 1)", "",
                  "| transcription | N | guess | sections | converged | mean (ms) | median (ms) | max (ms) | "
                  "mean iterations |", "|" + "---|" * 9]
        for r in results["sections"]:
            lines.append(f"| {r['transcription']} | {r['N']} | {r['guess']} | {r['sections']} | {r['converged']} | "
                         f"{1e3 * r['mean_s']:.0f} | {1e3 * r['median_s']:.0f} | {1e3 * r['max_s']:.0f} | "
                         f"{r['mean_iterations']:.0f} |")
        lines.append("")
    if "contact" in results:
        lines += ["## The cold step with the ground-reaction rows (forward, step 1, standard guess)", "",
                  "Unilateral contact and a friction cone (μ = 0.8) at every node, against the same step without them. "
                  "The rows are compiled per node (`NLPBuilder.constrain_columns`).", "",
                  "| transcription | N | contact rows | constraints | status | solve (s) | iterations | "
                  "derivatives (s) |",
                  "|" + "---|" * 8]
        for r in results["contact"]:
            lines.append(f"| {r['transcription']} | {r['N']} | {'yes' if r['contact_rows'] else 'no'} | "
                         f"{r['constraints']} | {r['status']} | {r['solve_s']:.3f} | {r['iterations']} | "
                         f"{r['derivative_s']:.3f} |")
        lines.append("")
    if "scaling" in results:
        lines += ["## Scalings against IPOPT's defaults", "",
                  "Same problems, same guesses (forward, step 1). objective: IPOPT's `nlp_scaling_obj_target_gradient "
                  "= 1`; nominal: variables and constraint rows (`scaling = \"nominal\"`, "
                  "gaitbench/problem/scaling.py). "
                  "Objective: the cold step's, or the median over the sections; \"lower\" counts the sections whose "
                  "objective the scaled solve brought below the default's by more than 1e-9 (relative).", "",
                  "| transcription | N | problem | IPOPT | converged | mean (ms) | mean iterations | objective | "
                  "lower |", "|" + "---|" * 9]
        rows = results["scaling"]
        for r in rows:
            default = next(d for d in rows if d["ipopt"] == "default" and d["problem"] == r["problem"]
                           and d["transcription"] == r["transcription"] and d["N"] == r["N"])
            lower = sum(new < old - 1e-9 * abs(old) for old, new in zip(default["objectives"], r["objectives"],
                                                                         strict=True))
            compared = "—" if r is default else f"{lower} of {len(r['objectives'])}"
            lines.append(f"| {r['transcription']} | {r['N']} | {r['problem']} | {r['ipopt']} | {r['converged']} | "
                         f"{1e3 * r['mean_s']:.0f} | {r['mean_iterations']:.0f} | "
                         f"{np.median(r['objectives']):.3g} | "
                         f"{compared} |")
        lines.append("")
    if results.get("walks"):
        lines += [f"## Whole walks (forward, first {results['walks'][0]['steps']} steps)", "",
                  "| transcription | N | strategy | workers | complete | ACOT | wall (s) |", "|" + "---|" * 7]
        for r in results["walks"]:
            acot = "—" if r["acot"] is None else f"{r['acot']:.5f}"
            lines.append(f"| {r['transcription']} | {r['N']} | {r['strategy']} | {r['workers']} | {r['complete']} "
                         f"| {acot} | {r['wall_s']:.1f} |")
        lines.append("")
    suites = [r for part in ("suite", "suite-all", "suite-all-large", "suite-all-large-scaled")
              for r in results.get(part, [])]
    if suites:
        lines += ["## Suite wall time", ""]
        for r in suites:
            fit = r["extrapolated"]
            methods = {}
            for label, value in fit["methods"].items():
                methods.setdefault(label.split(" ")[-1], []).append(value["suite_case_time_s"])
            limit = (f", case time limit {r['time_limit_s']} s, reached by {r['at_time_limit']}"
                     if "time_limit_s" in r else "")
            only = f", methods {', '.join(r['methods'])} only" if r.get("methods") else ""
            if r.get("ipopt_options"):
                only += ", IPOPT with " + ", ".join(f"`{k} = {v}`" for k, v in r["ipopt_options"].items())
            case_time = sum(row["wall_s"] for row in r["per_case"])
            lines += [f"`{r.get('suite', 'thesis-forward')}` sampled at N = {r['sample_N']} ({r['cases']} cases"
                      f"{only}{limit}), `--jobs {r['jobs']}`: "
                      f"measured {r['wall_s']:.0f} s ({case_time:.0f} s of case time). Extrapolated to the whole "
                      f"suite (N = 10…200) with a power law per experiment and method: "
                      f"{fit['case_time_s'] / 3600:.1f} h of case time, at least "
                      f"{fit['wall_s_lower_bound'] / 3600:.1f} h of wall time with {r['jobs']} job(s). "
                      "Case time by method: "
                      + ", ".join(f"{m} {sum(t) / 3600:.1f} h" for m, t in sorted(methods.items()))
                      + "; exponents: " + ", ".join(f"{m} {v['exponent']:.2f}" for m, v in fit["methods"].items())
                      + ".", ""]
    for r in [*results.get("suite-forward-full", []), *results.get("suite-forward-full-scaled", []),
              *results.get("suite-all-rest", [])]:
        case_time = sum(row["wall_s"] for row in r["per_case"])
        by_method = {}
        for row in r["per_case"]:
            by_method[row["method"]] = by_method.get(row["method"], 0.0) + row["wall_s"]
        schedule = r.get("list_schedule_s", {})
        experiments = f" (experiments {', '.join(r['experiments'])})" if r.get("experiments") else ""
        lines += [f"Whole `{r['suite']}`{experiments}, N = 10…200, methods {', '.join(r['methods'])} "
                  f"({r['cases']} cases, "
                  f"case time limit {r['time_limit_s']} s, reached by {r['at_time_limit']})"
                  + "".join(f", IPOPT with `{k} = {v}`" for k, v in r.get("ipopt_options", {}).items())
                  + f", `--jobs {r['jobs']}`: "
                  f"measured {r['wall_s']:.0f} s ({r['wall_s'] / 3600:.2f} h) of wall time, {case_time:.0f} s of "
                  "case time (about what `--jobs 1` would take). Case time by method: "
                  + ", ".join(f"{m} {t:.0f} s" for m, t in by_method.items())
                  + (f". The same case times scheduled on {r['jobs']} workers: "
                     + ", ".join(f"{order} {t:.0f} s" for order, t in schedule.items()) if schedule else "")
                  + ".", ""]
        if "with_forward" in r:
            whole = r["with_forward"]
            commit = whole["forward_git_commit"] or "not recorded"
            lines += [f"With `suite-forward-full`'s forward cases (commit {commit}), all of `{r['suite']}`'s IPOPT "
                      f"part, {whole['cases']} cases: {whole['case_time_s']:.0f} s "
                      f"({whole['case_time_s'] / 3600:.2f} h) of case time; the two runs took "
                      f"{whole['wall_s_measured_sum']:.0f} s of wall time together; the measured case times "
                      f"scheduled on {r['jobs']} workers in the runner's order, largest N first, finish at "
                      f"{whole['list_schedule_s']:.0f} s ({whole['list_schedule_s'] / 3600:.2f} h).", ""]
    if "executors" in results:
        lines += ["## Executors (the same cases, 2 jobs)", "",
                  "| executor | sample N | cases | wall (s) | case time (s) |", "|" + "---|" * 5]
        for r in results["executors"]:
            case_time = sum(row["wall_s"] for row in r["per_case"])
            lines.append(f"| {r['executor']} | {r['sample_N']} | {r['cases']} | {r['wall_s']:.0f} | {case_time:.0f} |")
        lines.append("")
    return "\n".join(lines)
