"""One stored gait: its time series, ground reactions and push-off impulses, figures, and a stick-figure animation.

The walk is read from the store (``cases/<key>/walk.json`` + ``walk.npz``, written by
:meth:`gaitbench.walk.WalkResult.save`). Times are made global (each step starts where the previous one ended).
Ground reactions are computed from the stored nodal trajectory with the 4-DOF model's exact constraint force
(:meth:`gaitbench.mechanics.BipedModel.forward_dynamics`, DECISIONS §2); the 2-DOF First-Phase model pins its
stance foot and defines no ground reaction, and the report says so instead of inventing one.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gaitbench.reports.figures import Figure, plt, render, slug

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
    reaction: np.ndarray | None = None  # (N, 2): friction f_t, normal f_n


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

    @property
    def label(self) -> str:
        partial = ", partial walk" if self.partial else ""
        return f"{self.experiment}, {self.method}, N = {self.N} (case {self.case_key}{partial})"


def load_gait(store_dir: str | Path, case: Any, registry=None) -> Gait:
    """The gait of one stored case (a row of :func:`gaitbench.reports.tables.prepare`)."""
    from gaitbench.mechanics import BipedModel
    from gaitbench.plugins import load_registry

    store_dir = Path(store_dir)
    path = store_dir / case["walk_path"]
    data = json.loads(path.read_text())
    arrays = {}
    if "trajectories" in data:
        with np.load(path.parent / data["trajectories"]) as npz:
            arrays = {key: npz[key] for key in npz.files}
    registry = registry or load_registry()
    options = case["experiment_options"] if isinstance(case["experiment_options"], dict) else {}
    experiment = registry.create("experiment", data["experiment"], **options)
    phase = data.get("phase", "second")
    notes = []
    model = BipedModel(experiment.robot, 4) if phase == "second" else None
    if model is None:
        notes.append("Ground reactions: not shown. This walk uses the 2-DOF First-Phase model, whose stance foot is "
                     "pinned; gaitbench's model defines no ground reaction for it (the 4-DOF model does).")
    footholds = experiment.terrain.footholds()
    steps, start = [], 0.0
    for step in data["steps"]:
        prefix = f"step{int(step['index']):02d}"
        if f"{prefix}_q" not in arrays:
            break
        t = np.asarray(arrays[f"{prefix}_t"], dtype=float)
        tau_t = np.asarray(arrays[f"{prefix}_tau_t"], dtype=float)
        q, dq = np.asarray(arrays[f"{prefix}_q"], dtype=float), np.asarray(arrays[f"{prefix}_dq"], dtype=float)
        tau = np.asarray(arrays[f"{prefix}_tau"], dtype=float).reshape(len(tau_t), -1)
        gait_step = GaitStep(int(step["index"]), int(step["stance"]), start + t, q, dq, start + tau_t, tau,
                             step.get("push_off_impulse"), step.get("cot"), step.get("max_defect"),
                             step.get("resim_error"))
        if model is not None:
            foot = footholds[gait_step.index - 1]
            reactions = []
            for k in range(len(t)):
                torque = [np.interp(t[k], tau_t, tau[:, j]) for j in range(tau.shape[1])]
                _, reaction = model.forward_dynamics(np.r_[q[k], foot], np.r_[dq[k], 0.0, 0.0], torque,
                                                     gait_step.stance)
                reactions.append(np.asarray(reaction, dtype=float).reshape(-1)[:2])
            gait_step.reaction = np.array(reactions)
        steps.append(gait_step)
        start = float(gait_step.t[-1])
    if case["is_dc"]:
        notes.append("Decrease & Conquer: the stored trajectory is the chosen synthesized (node-wise patchwork) "
                     "trajectory whose COT is the claim; it need not satisfy the dynamics (see its max defect). "
                     "The verified ACOT is that of the polished trajectories, re-solved from it, which the store "
                     "does not keep (docs/deviations.md).")
    return Gait(case_key=case["case_key"], experiment=case["experiment"], method=case["method"],
                strategy=case["strategy"], transcription=case["transcription"], N=int(case["N"]), phase=phase,
                acot=_float(case["acot"]), claimed_acot=_float(case["claimed_acot"]), steps=steps,
                footholds=footholds, leg_length=experiment.robot.l, notes=notes,
                partial=not bool(case.get("complete", case["status"] == "solved")))


def _float(value: Any) -> float | None:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if np.isfinite(value) else None


def _boundaries(ax, gait: Gait) -> None:
    for step in gait.steps[:-1]:
        ax.axvline(step.t[-1], color="gray", lw=0.6, ls=":")


def gait_figures(gait: Gait) -> list[Figure]:
    """Angles, velocities, hip torques, ground reactions (butterfly diagram) and push-off impulses."""
    if not gait.steps:
        return []
    key = slug(gait.case_key)
    figures = []
    for attribute, ylabel, title, role, fig_id in (
            ("q", "angle (rad)", "Leg angles", "angles", "angles"),
            ("dq", "angular velocity (rad/s)", "Leg angular velocities", "velocities", "velocities")):
        fig, ax = plt.subplots(figsize=(7, 3.2))
        for leg in (0, 1):
            t = np.concatenate([s.t for s in gait.steps])
            values = np.concatenate([getattr(s, attribute)[:, leg] for s in gait.steps])
            ax.plot(t, values, ".-", ms=3, label=f"leg {leg + 1}")
        _boundaries(ax, gait)
        ax.set_xlabel("t (s)")
        ax.set_ylabel(ylabel)
        ax.legend(fontsize=7)
        figures.append(Figure(f"fig-gait-{fig_id}-{key}", f"{title}: {gait.label}",
                              f"{title} at the nodes of every step (dotted lines: heel strikes)." + _thesis(gait, role),
                              render(fig)))
    fig, ax = plt.subplots(figsize=(7, 3.2))
    for leg in (0, 1):
        t = np.concatenate([s.tau_t for s in gait.steps])
        values = np.concatenate([s.tau[:, leg] for s in gait.steps])
        ax.plot(t, values, ".-", ms=3, label=f"τ{leg + 1}")
    _boundaries(ax, gait)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("hip torque (N·m)")
    ax.legend(fontsize=7)
    figures.append(Figure(f"fig-gait-torques-{key}", f"Hip torques: {gait.label}",
                          "Hip torques τ1, τ2 at the control times of each step." + _thesis(gait, "torques"),
                          render(fig)))
    if all(step.reaction is not None for step in gait.steps):
        fig, ax = plt.subplots(figsize=(7, 3.2))
        t = np.concatenate([s.t for s in gait.steps])
        reaction = np.vstack([s.reaction for s in gait.steps])
        ax.plot(t, reaction[:, 1], ".-", ms=3, label="normal f_n")
        ax.plot(t, reaction[:, 0], ".-", ms=3, label="friction f_t")
        ax.axhline(0, color="black", lw=0.6)
        _boundaries(ax, gait)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("ground reaction (N)")
        ax.legend(fontsize=7)
        figures.append(Figure(f"fig-gait-grf-{key}", f"Ground reactions (butterfly diagram): {gait.label}",
                              "Stance-foot ground reaction, friction and normal components, computed at each node "
                              "as the exact constraint force of the 4-DOF model (DECISIONS §2)."
                              + _thesis(gait, "ground_reaction"), render(fig)))
    impulses = [(s.index, s.push_off) for s in gait.steps if s.push_off is not None]
    if impulses:
        fig, ax = plt.subplots(figsize=(5, 3))
        ax.bar([i for i, _ in impulses], [value for _, value in impulses], color="tab:orange")
        ax.set_xlabel("step")
        ax.set_ylabel("push-off impulse (N·s)")
        ax.set_xticks([i for i, _ in impulses])
        figures.append(Figure(f"fig-gait-push-off-{key}", f"Push-off impulses: {gait.label}",
                              "The instantaneous push-off impulse along the stance leg at the end of each step."
                              + _thesis(gait, "push_off"), render(fig)))
    return figures


def _thesis(gait: Gait, role: str) -> str:
    from gaitbench.reports import thesis_values

    name = thesis_values.figure(gait.experiment, role)
    return f" Thesis counterpart: {name}." if name else ""


def stick_frames(gait: Gait, frame_rate: float = FRAME_RATE) -> list[list[float]]:
    """Frames of the walk: [stance foot x, y, hip x, y, swing foot x, y] at ``frame_rate`` (Convention A,
    DECISIONS §1; nodal angles linearly interpolated)."""
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
