"""The retarget of :mod:`.transfer` as a per-frame plan, for a page that drives a character live from joints
it has just computed (``sm export-web --rig``: the streaming dancer's SMPL-24 joints onto the user's
character).

:func:`live_plan` does the whole-clip work once, on the source's rest pose: which rig nodes are driven and by
which source bones (:func:`~.transfer.driven_tips`), each driven node's rest direction (and rest frame for the
hips and the torso), its rest rotation and its parent's, the leg-length scale and the hips' height offset. A
frame is then :func:`apply_live_plan` (the page runs the same steps in JavaScript):

- ``D`` of a step: ``frame(current, second) @ rest_frame.T`` for the hips (second: the hip axis) and torso
  bones (the shoulder axis), else ``swing(P @ rest_dir, current) @ P`` with ``P`` the nearest driven
  ancestor's ``D`` (identity for none), exactly as :func:`~.transfer.retarget` does for every frame;
- the node's local rotation ``(P @ R_rest_parent).T @ D @ R_rest``;
- the hips' translation: ``inverse(parent's rest world) @ (scale * source hips + (0, lift, 0))``, with the
  floor lift a constant (the clip-wide one of :func:`~.transfer.retarget` needs the whole clip).
"""

from __future__ import annotations

import numpy as np

from skeleton_mamba.tasks.motion.retarget.rig import Rig
from skeleton_mamba.tasks.motion.retarget.transfer import (
    _TORSO,
    _frame,
    _rotation,
    _swing,
    driven_tips,
    retarget,
)

__all__ = ["apply_live_plan", "live_plan"]


def live_plan(rig: Rig, rest: np.ndarray, names_to_bones: dict[str, int]) -> dict:
    """The plan (JSON-able) of driving ``rig`` from a source with humanoid bones ``names_to_bones`` (bone ->
    source joint) whose rest pose is ``rest`` (J, 3), metres +Y up, feet on the floor."""
    rest = np.asarray(rest, np.float64)
    tips = driven_tips(rig, rest[None], names_to_bones)
    rest_pos, rest_rot = rig.rest_world[:, :3, 3], _rotation(rig.rest_world)
    node_bone = {rig.bones[b]: b for b in tips}
    step_of: dict[int, int] = {}  # node -> the step that drives it
    steps = []
    for j in rig.order:
        if j not in node_bone:
            continue
        b = node_bone[j]
        ancestor, p = -1, rig.parents[j]
        while p >= 0 and ancestor < 0:
            ancestor, p = step_of.get(p, -1), rig.parents[p]
        kind = "hips" if b == "hips" else "torso" if b in _TORSO else "swing"
        rest_dir = rest_pos[rig.bones[tips[b]]] - rest_pos[j]
        pair = ("leftUpperLeg", "rightUpperLeg") if kind == "hips" else ("leftUpperArm", "rightUpperArm")
        second = rest_pos[rig.bones[pair[0]]] - rest_pos[rig.bones[pair[1]]]
        parent = rig.parents[j]
        steps.append({
            "node": j, "bone": b, "ancestor": ancestor, "kind": kind,
            "source": [names_to_bones[b], names_to_bones[tips[b]]],
            "axis": [names_to_bones[pair[0]], names_to_bones[pair[1]]],
            "rest_dir": rest_dir.tolist(),
            "rest_frame": _frame(rest_dir, second).tolist(),
            "rest_rotation": rest_rot[j].tolist(),
            "parent_rest_rotation": (rest_rot[parent] if parent >= 0 else np.eye(3)).tolist(),
        })  # fmt: skip
        step_of[j] = len(steps) - 1
    posed = retarget(rig, rest[None], names_to_bones)  # the rest pose: both feet on the floor
    hips = rig.bones["hips"]
    lift = float(posed.positions[0, hips, 1] - posed.scale * rest[names_to_bones["hips"], 1])
    parent = rig.parents[hips]
    inverse = np.linalg.inv(rig.rest_world[parent]) if parent >= 0 else np.eye(4)
    return {
        "steps": steps, "hips": hips, "source_hips": names_to_bones["hips"], "scale": float(posed.scale),
        "lift": lift, "hips_parent_inverse": inverse.tolist(),
    }  # fmt: skip


def apply_live_plan(plan: dict, joints: np.ndarray) -> tuple[dict[int, np.ndarray], np.ndarray]:
    """One frame of source ``joints`` (J, 3) through ``plan``: rig node -> local rotation (3, 3), and the
    hips' local translation (3,). The reference the page's JavaScript is tested against."""
    joints = np.asarray(joints, np.float64)
    deltas, local = [], {}
    for s in plan["steps"]:
        parent_delta = deltas[s["ancestor"]] if s["ancestor"] >= 0 else np.eye(3)
        a, b = s["source"]
        current = joints[b] - joints[a]
        if s["kind"] == "swing":
            delta = _swing(parent_delta @ np.asarray(s["rest_dir"]), current) @ parent_delta
        else:
            second = joints[s["axis"][0]] - joints[s["axis"][1]]
            delta = _frame(current, second) @ np.asarray(s["rest_frame"]).T
        deltas.append(delta)
        parent_world = parent_delta @ np.asarray(s["parent_rest_rotation"])
        local[s["node"]] = parent_world.T @ delta @ np.asarray(s["rest_rotation"])
    path = plan["scale"] * joints[plan["source_hips"]] + np.array([0.0, plan["lift"], 0.0])
    inverse = np.asarray(plan["hips_parent_inverse"])
    return local, inverse[:3, :3] @ path + inverse[:3, 3]
