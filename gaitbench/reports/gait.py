"""One stored gait: its time series, ground reactions and push-off impulses, figures, and a stick-figure animation.

The walk is read from the store (``cases/<key>/walk.json`` + ``walk.npz``, a walk file of
:mod:`gaitbench.solve.walk_file`). Times are made global (each step starts where the previous one ended).
Ground reactions are computed from the stored nodal trajectory with the 4-DOF model's exact constraint force
(:meth:`gaitbench.model.mechanics.BipedModel.forward_dynamics`, docs/model.md §2); the 2-DOF First-Phase model pins its
stance foot and defines no ground reaction, and the report says so instead of inventing one.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gaitbench.reports.figures import Figure, legend_below, render, slug, subplots

if TYPE_CHECKING:
    from gaitbench.solve.walk_file import WalkFile

FRAME_RATE = 30.0
"""Frames per second of the stick-figure animation (nodal values linearly interpolated)."""


@dataclass
class GaitStep:
    index: int
    stance: int
    t: np.ndarray  # global times of the nodes
    q: np.ndarray  # (N, 2) leg angles, leg order
    dq: np.ndarray
    tau_t: np.ndarray
    tau: np.ndarray
    push_off: float | None
    cot: float | None
    max_defect: float | None
    resim_error: float | None
    reaction: np.ndarray | None = None  # (N, 2): horizontal f_x, vertical f_y


@dataclass
class Gait:
    case_key: str
    experiment: str
    method: str
    strategy: str
    transcription: str
    N: int
    phase: str
    acot: float | None
    claimed_acot: float | None
    steps: list[GaitStep]
    footholds: np.ndarray
    leg_length: float
    notes: list[str] = field(default_factory=list)
    partial: bool = False
    """The walk stopped early (a ``--gait`` choice can be one): its label, and so every figure's title, says so."""
    verification_failure: str | None = None
    """Why a complete walk failed verification (a ``--gait`` choice can be one): its label says so, and its ACOT
    is shown as the unranked figure it is, never as a verified one."""
    unranked_acot: float | None = None
    """An unverified walk's ACOT of its reported motions."""
    overlay: list[GaitStep] = field(default_factory=list)
    """Decrease and conquer's chosen (patchwork) trajectory when :attr:`steps` are the polished ones: drawn dashed."""
    trajectory: str = "walk"
    """``walk`` (each step's own trajectory) or ``polished`` (the verified trajectory of decrease and conquer)."""

    @property
    def overlay_by_index(self) -> dict[int, GaitStep]:
        return {step.index: step for step in self.overlay}

    @property
    def label(self) -> str:
        status = ", partial walk" if self.partial else ", unverified walk" if self.verification_failure else ""
        return f"{self.experiment}, {self.method}, N = {self.N} (case {self.case_key}{status})"


def load_gait(store_dir: str | Path, case: Any, registry=None) -> Gait:
    """The gait of one stored case (a row of :func:`gaitbench.reports.case_frame.prepare`).

    For decrease and conquer, the gait is the verified trajectory, each step polished (re-solved from the chosen
    patchwork), when the walk stored it for every step; the chosen patchwork is kept as :attr:`Gait.overlay`.
    """
    from gaitbench.model.mechanics import BipedModel
    from gaitbench.plugins import load_registry
    from gaitbench.solve.walk_file import POLISHED, read_walk

    walk = read_walk(Path(store_dir) / case["walk_path"])
    registry = registry or load_registry()
    row_options = case["experiment_options"] if isinstance(case["experiment_options"], dict) else {}
    experiment = walk.experiment(registry, unrecorded_options=row_options)
    phase = walk.header.get("phase", "second")
    notes = []
    model = BipedModel(experiment.robot, 4) if phase == "second" else None
    if model is None:
        notes.append("Ground reactions: not shown. This walk uses the 2-DOF First-Phase model, whose stance foot is "
                     "pinned; gaitbench's model defines no ground reaction for it (the 4-DOF model does).")
    footholds = experiment.terrain.footholds()
    own = _steps(walk, walk.steps, lambda step: step)
    polished = _steps(walk, walk.steps[:len(own)], lambda step: (step.get("details") or {}).get(POLISHED), POLISHED)
    overlay: list[GaitStep] = []
    trajectory = "walk"
    if own and len(polished) == len(own):
        steps, overlay, trajectory = polished, own, POLISHED
    else:
        steps = own
    if model is not None:
        for gait_step in steps:
            gait_step.reaction = _reactions(model, footholds[gait_step.index - 1], gait_step)
        held = bool((walk.header.get("problem_options") or {}).get("unilateral_contact"))
        pulling = _pulling_note(steps, footholds, experiment.robot.total_mass * experiment.robot.g, held)
        if pulling:
            notes.append(pulling)
    if case["is_dc"] and trajectory == POLISHED:
        worst = max((step.max_defect for step in overlay if step.max_defect is not None), default=None)
        notes.append("Decrease & Conquer: the gait shown is the verified trajectory, the motion each step reports: "
                     "the complete problem re-solved (polished) from the chosen synthesized trajectory, or the "
                     "complete Second Phase solution where that is cheaper or the polish failed; the walk's ACOT "
                     "is this trajectory's. The chosen trajectory itself, a node-wise patchwork of NLP solutions "
                     "whose COT is the thesis's claim, is drawn dashed"
                     + (f"; it need not satisfy the dynamics (largest dynamics residual {worst:.3g})" if worst
                        is not None else "") + ". "
                     + ("Each step starts from the post-impact state of the motion before it, so the steps join "
                        "into one motion." if all("motion" in _reported(step) for step in walk.steps) else
                        "This walk was stored when the walk chained the patchworks: each polished step starts where "
                        "the previous patchwork ended, so the polished steps need not join at a heel strike "
                        "(`gaitbench verify` measures by how much)."))
        stand_ins = [(step["index"], _reported(step).get("why", "the polish failed"))
                     for step in walk.steps if _reported(step).get("stand_in")]
        for index, why in stand_ins:
            notes.append(f"Step {index}: the complete Second Phase solution (the same problem from the same state, "
                         f"solved from the First-Phase seed) stands in for the polish: {why}.")
    elif case["is_dc"]:
        notes.append("Decrease & Conquer: the stored trajectory is the chosen synthesized (node-wise patchwork) "
                     "trajectory whose COT is the claim; it need not satisfy the dynamics (see its max defect). "
                     "The verified ACOT is that of the polished trajectories, re-solved from it, which this walk "
                     "does not hold for every step (solved with polish = false, a polish that failed, or stored "
                     "before gaitbench kept them).")
    complete = bool(case.get("complete", case["status"] == "solved"))
    unverified = case.get("verification_failure") if complete and not case.get("ranked", True) else None
    return Gait(case_key=case["case_key"], experiment=case["experiment"], method=case["method"],
                strategy=case["strategy"], transcription=case["transcription"], N=int(case["N"]), phase=phase,
                acot=_float(case["acot"]), claimed_acot=_float(case["claimed_acot"]), steps=steps,
                footholds=footholds, leg_length=experiment.robot.l, notes=notes,
                partial=not complete, overlay=overlay, trajectory=trajectory,
                verification_failure=unverified,
                unranked_acot=_float(case.get("verified_acot")) if unverified else None)


def _steps(walk: WalkFile, records: list[dict], figures, name: str = "") -> list[GaitStep]:
    """The walk's steps with arrays (``name``: ``polished`` for the polished trajectories'), on global times (each
    step starts where the one before ended), up to the first without; ``figures(step)`` is the dict holding the
    step's COT, push-off impulse, max defect and resim error."""
    steps, start = [], 0.0
    for step in records:
        arrays = walk.step_arrays(int(step["index"]), name)
        numbers = figures(step)
        if "q" not in arrays or not isinstance(numbers, dict):
            break
        t = np.asarray(arrays["t"], dtype=float)
        tau_t = np.asarray(arrays["tau_t"], dtype=float)
        q, dq = np.asarray(arrays["q"], dtype=float), np.asarray(arrays["dq"], dtype=float)
        tau = np.asarray(arrays["tau"], dtype=float).reshape(len(tau_t), -1)
        push_off = float(np.asarray(arrays["push_off"]).ravel()[0]) if "push_off" in arrays \
            else numbers.get("push_off_impulse")
        steps.append(GaitStep(int(step["index"]), int(step["stance"]), start + t, q, dq, start + tau_t, tau, push_off,
                              numbers.get("cot"), numbers.get("max_defect"), numbers.get("resim_error")))
        start = float(steps[-1].t[-1])
    return steps


def _reactions(model, foot: np.ndarray, step: GaitStep) -> np.ndarray:
    """The stance foot's ground reaction (horizontal f_x, vertical f_y) at each node, torques interpolated to the
    node times."""
    local, local_tau = step.t - step.t[0], step.tau_t - step.t[0]
    reactions = []
    for k in range(len(local)):
        torque = [np.interp(local[k], local_tau, step.tau[:, j]) for j in range(step.tau.shape[1])]
        _, reaction = model.forward_dynamics(np.r_[step.q[k], foot], np.r_[step.dq[k], 0.0, 0.0], torque, step.stance)
        reactions.append(np.asarray(reaction, dtype=float).reshape(-1)[:2])
    return np.array(reactions)


PULL_TOLERANCE = 1e-6
"""A normal force above −this × the robot's weight is no pull: a solver holds f_n ≥ 0 only to its tolerance."""


def _pulling_note(steps: list[GaitStep], footholds: np.ndarray, weight: float, held: bool = False) -> str | None:
    """Where the stance foot's reaction, normal to the step's chord, pulls on the ground: a motion a foot resting on
    the ground cannot make, which only ``unilateral_contact`` rules out (docs/model.md §2); ``held``: the walk was
    solved with it, so a pull here means the constraint held only at the nodes it covers."""
    normals = []
    for step in steps:
        dx, dy = footholds[step.index] - footholds[step.index - 1]
        theta = np.arctan2(dy, dx)
        normals.append((step.index, (-np.sin(theta) * step.reaction[:, 0] + np.cos(theta) * step.reaction[:, 1])))
    pulled = sum(int((normal < -PULL_TOLERANCE * weight).sum()) for _, normal in normals)
    if not pulled:
        return None
    index, worst = min(((i, float(normal.min())) for i, normal in normals), key=lambda pair: pair[1])
    total = sum(len(normal) for _, normal in normals)
    why = ("The walk was solved with `unilateral_contact`, which holds at the nodes it covers (DMOC: not its two "
           "end nodes; docs/model.md §2)." if held else
           "The walk was solved without the unilateral-contact constraint (`unilateral_contact`, off in the thesis "
           "suites, as the thesis has none; docs/model.md §2); verification does not check it.")
    return (f"Contact: the stance foot pulls on the ground at {pulled} of {total} nodes, down to "
            f"{-worst / weight:.2f} body weights (step {index}): no foot resting on the ground can. {why}")


def _float(value: Any) -> float | None:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if np.isfinite(value) else None


def _boundaries(ax, gait: Gait) -> None:
    for step in gait.steps[:-1]:
        ax.axvline(step.t[-1], color="gray", lw=0.6, ls=":")


PATCHWORK = "chosen patchwork (claimed)"
"""How the overlay of decrease and conquer's chosen trajectory is labelled in the gait figures."""


def _series(ax, gait: Gait, attribute: str, times: str, names: tuple[str, str]) -> None:
    """Both legs' values over the walk; the overlay (D&C's patchwork) dashed and lighter, in the same colours."""
    colors = ("tab:blue", "tab:orange")
    for leg in (0, 1):
        t = np.concatenate([getattr(s, times) for s in gait.steps])
        values = np.concatenate([getattr(s, attribute)[:, leg] for s in gait.steps])
        ax.plot(t, values, ".-", ms=3, color=colors[leg], label=names[leg])
    for leg in (0, 1):
        if gait.overlay:
            t = np.concatenate([getattr(s, times) for s in gait.overlay])
            values = np.concatenate([getattr(s, attribute)[:, leg] for s in gait.overlay])
            ax.plot(t, values, "--", lw=0.9, color=colors[leg], alpha=0.55, label=f"{names[leg]}, {PATCHWORK}")


def _shown(gait: Gait) -> str:
    """What the figures draw, said in their captions."""
    if gait.trajectory == "polished":
        return (" Solid: the reported trajectory (each step polished, re-solved from the chosen trajectory, or the "
                "complete Second Phase solution standing in); dashed: the chosen synthesized patchwork, whose COT is "
                "the claim.")
    return ""


def gait_figures(gait: Gait) -> list[Figure]:
    """Angles, velocities, hip torques, ground reactions (butterfly diagram) and push-off impulses; for decrease
    and conquer with its polished trajectory stored, that trajectory, with the chosen patchwork dashed over it."""
    if not gait.steps:
        return []
    key = slug(gait.case_key)
    shown = _shown(gait)
    figures = []
    for attribute, ylabel, title, role, fig_id in (
            ("q", "angle (rad)", "Leg angles", "angles", "angles"),
            ("dq", "angular velocity (rad/s)", "Leg angular velocities", "velocities", "velocities")):
        fig, ax = subplots(figsize=(7, 3.2))
        _series(ax, gait, attribute, "t", ("leg 1", "leg 2"))
        _boundaries(ax, gait)
        ax.set_xlabel("t (s)")
        ax.set_ylabel(ylabel)
        legend_below(fig)
        figures.append(Figure(f"fig-gait-{fig_id}-{key}", f"{title}: {gait.label}",
                              f"{title} at the nodes of every step (dotted lines: heel strikes)." + shown
                              + _thesis(gait, role), render(fig)))
    fig, ax = subplots(figsize=(7, 3.2))
    _series(ax, gait, "tau", "tau_t", ("τ1", "τ2"))
    _boundaries(ax, gait)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("hip torque (N·m)")
    legend_below(fig)
    figures.append(Figure(f"fig-gait-torques-{key}", f"Hip torques: {gait.label}",
                          "Hip torques τ1, τ2 at the control times of each step." + shown + _thesis(gait, "torques"),
                          render(fig)))
    if all(step.reaction is not None for step in gait.steps):
        fig, ax = subplots(figsize=(7, 3.2))
        t = np.concatenate([s.t for s in gait.steps])
        reaction = np.vstack([s.reaction for s in gait.steps])
        ax.plot(t, reaction[:, 1], ".-", ms=3, label="vertical f_y")
        ax.plot(t, reaction[:, 0], ".-", ms=3, label="horizontal f_x")
        ax.axhline(0, color="black", lw=0.6)
        _boundaries(ax, gait)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("ground reaction (N)")
        legend_below(fig)
        figures.append(Figure(f"fig-gait-grf-{key}", f"Ground reactions (butterfly diagram): {gait.label}",
                              "Stance-foot ground reaction, horizontal f_x and vertical f_y (world axes, as the "
                              "thesis plots it; on a slope not the friction and normal components), computed at "
                              "each node "
                              "as the exact constraint force of the 4-DOF model (docs/model.md §2)"
                              + (", of the verified trajectory." if gait.trajectory == "polished" else ".")
                              + _thesis(gait, "ground_reaction"), render(fig)))
    impulses = [(s.index, s.push_off) for s in gait.steps if s.push_off is not None]
    if impulses:
        fig, ax = subplots(figsize=(5, 3))
        claimed = {s.index: s.push_off for s in gait.overlay if s.push_off is not None}
        width = 0.4 if claimed else 0.8
        ax.bar([i - (width / 2 if claimed else 0) for i, _ in impulses], [value for _, value in impulses], width,
               color="tab:orange", label="verified" if claimed else None)
        if claimed:
            ax.bar([i + width / 2 for i in claimed], list(claimed.values()), width, color="none",
                   edgecolor="tab:orange", hatch="//", label=PATCHWORK)
            legend_below(fig)
        ax.set_xlabel("step")
        ax.set_ylabel("push-off impulse (N·s)")
        ax.set_xticks([i for i, _ in impulses])
        figures.append(Figure(f"fig-gait-push-off-{key}", f"Push-off impulses: {gait.label}",
                              "The instantaneous push-off impulse along the stance leg at the end of each step."
                              + (" Hatched: the chosen patchwork's." if claimed else "")
                              + _thesis(gait, "push_off"), render(fig)))
    return figures


def _thesis(gait: Gait, role: str) -> str:
    from gaitbench.reports import thesis_values

    name = thesis_values.figure(gait.experiment, role)
    return f" Thesis counterpart: {name}." if name else ""


def stick_frames(gait: Gait, frame_rate: float = FRAME_RATE) -> list[list[float]]:
    """Frames of the walk: [stance foot x, y, hip x, y, swing foot x, y] at ``frame_rate`` (Convention A,
    docs/model.md §1; nodal angles linearly interpolated)."""
    l = gait.leg_length  # noqa: E741
    frames = []
    for step in gait.steps:
        t0, t1 = float(step.t[0]), float(step.t[-1])
        count = max(2, int(round((t1 - t0) * frame_rate)) + 1)
        foot = gait.footholds[step.index - 1]
        st, sw = step.stance - 1, 2 - step.stance
        for t in np.linspace(t0, t1, count):
            q_st, q_sw = np.interp(t, step.t, step.q[:, st]), np.interp(t, step.t, step.q[:, sw])
            hip = foot + l * np.array([-np.sin(q_st), np.cos(q_st)])
            swing = hip + l * np.array([np.sin(q_sw), -np.cos(q_sw)])
            frames.append([round(float(v), 4) for v in (*foot, *hip, *swing)])
    return frames


def animation_svg(gait: Gait, element_id: str) -> str:
    """An inline SVG of the robot over its terrain (frame 0 drawn), animated by the page's script from the
    frames in its ``data-frames`` attribute."""
    frames = stick_frames(gait)
    if not frames:
        return ""
    points = np.array(frames).reshape(-1, 2)
    ground = gait.footholds[: len(gait.steps) + 1]
    everything = np.vstack([points, ground])
    margin = 0.3 * gait.leg_length
    x0, y0 = everything.min(axis=0) - margin
    x1, y1 = everything.max(axis=0) + margin
    width, height = x1 - x0, y1 - y0
    ground_points = " ".join(f"{x:.4f},{-y:.4f}" for x, y in ground)
    extended = f"{x0:.4f},{-ground[0][1]:.4f} {ground_points} {x1:.4f},{-ground[-1][1]:.4f}"
    first = frames[0]
    stroke = 0.03 * gait.leg_length
    return (
        f'<svg id="{element_id}" class="stick-figure" viewBox="{x0:.4f} {-y1:.4f} {width:.4f} {height:.4f}" '
        f'width="100%" height="{max(160, int(400 * height / max(width, 1e-9)))}" '
        f'xmlns="http://www.w3.org/2000/svg" data-frames=\'{json.dumps(frames, separators=(",", ":"))}\' '
        f'data-rate="{FRAME_RATE:g}">'
        f'<polyline points="{extended}" fill="none" stroke="#6b4f2a" stroke-width="{stroke:.4f}"/>'
        + "".join(f'<circle cx="{x:.4f}" cy="{-y:.4f}" r="{stroke:.4f}" fill="#6b4f2a"/>' for x, y in ground)
        + f'<line class="leg-stance" x1="{first[0]}" y1="{-first[1]}" x2="{first[2]}" y2="{-first[3]}" '
        f'stroke="#1f77b4" stroke-width="{stroke:.4f}" stroke-linecap="round"/>'
        f'<line class="leg-swing" x1="{first[2]}" y1="{-first[3]}" x2="{first[4]}" y2="{-first[5]}" '
        f'stroke="#d62728" stroke-width="{stroke:.4f}" stroke-linecap="round"/>'
        f'<circle class="hip" cx="{first[2]}" cy="{-first[3]}" r="{2 * stroke:.4f}" fill="#333"/>'
        "</svg>"
    )


def _reported(step: dict) -> dict:
    """A decrease-and-conquer step record's ``details["polished"]``: the motion it reports and why ({} if none)."""
    return (step.get("details") or {}).get("polished") or {}
