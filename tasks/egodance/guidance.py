"""Head guidance G_head: the egocentric camera trajectory steers the predicted head joint at sampling.

The EgoAIST++ camera sits at the eyes, ``c_t = p_15 + R_15 (0, up, forward)`` (``builder/camera.py``), so
the head joint target is ``p*_t = c_t - R_15 (0, up, forward)`` with ``R_15 = R_cam diag(-1, -1, 1)``.
At every sampling step the predicted clean motion x0_hat is moved down the gradient of
``G_head = sum_t ||FK(x0_hat)_15,t - p*_t||^2`` (a classifier-guidance style correction of x0; the exact
form and schedule are in the unreleased main paper, so weight and steps are options).
"""

from __future__ import annotations

import numpy as np
import torch

from skeleton_mamba.tasks.egodance.builder.camera import HEAD_TO_CAMERA
from skeleton_mamba.tasks.egodance.heading_frames import head_heading, head_rotation, yaw_matrices
from skeleton_mamba.tasks.egodance.representation import HEAD_JOINT, ROT, motion_joints
from skeleton_mamba.tasks.training.diffusion.samplers import GuidanceTerm

ROOT_JOINT = 0

__all__ = [
    "HeadGuidance",
    "HeadingGuidance",
    "head_guidance_objective",
    "head_pose_from_camera",
    "head_targets_from_camera",
]


def head_pose_from_camera(
    positions: np.ndarray, rotations: np.ndarray, forward_offset: float = 0.10, up_offset: float = 0.06
) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres (T, 3) and camera-to-world rotations (T, 3, 3) -> the head joint's positions (T, 3)
    and head-to-world rotations R_15 (T, 3, 3)."""
    head_rot = rotations @ HEAD_TO_CAMERA.T  # HEAD_TO_CAMERA is its own inverse (diag(-1, -1, 1))
    return positions - head_rot @ np.array([0.0, up_offset, forward_offset]), head_rot


def head_targets_from_camera(
    positions: np.ndarray, rotations: np.ndarray, forward_offset: float = 0.10, up_offset: float = 0.06
) -> np.ndarray:
    """Camera centres (T, 3) and camera-to-world rotations (T, 3, 3) -> head joint positions (T, 3)."""
    return head_pose_from_camera(positions, rotations, forward_offset, up_offset)[0]


def head_guidance_objective(
    x0: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None
) -> torch.Tensor:
    """G_head (B,): summed squared head-joint error; x0 (B, T, 24, 10), target (B, T, 3), mask (B, T)."""
    err = (motion_joints(x0)[..., HEAD_JOINT, :] - target).pow(2).sum(-1)
    if mask is not None:
        err = err * mask.to(err.dtype)
    return err.sum(-1)


class HeadGuidance(GuidanceTerm):
    """Gradient steps on x0_hat towards the head targets.

    Args:
        target: (B, T, 3) head joint positions in the motion's (canonical) frame.
        weight: step size per gradient step (x0 <- x0 - weight * grad G_head).
        steps: gradient steps per sampling step.
        mask: (B, T) bool frames where a target exists (None: all).
        start_fraction: apply only while t < start_fraction * T (1: at every step).
        num_steps: T of the diffusion (needed with ``start_fraction < 1``).
    """

    def __init__(
        self,
        target: torch.Tensor,
        weight: float = 0.05,
        steps: int = 1,
        mask: torch.Tensor | None = None,
        start_fraction: float = 1.0,
        num_steps: int = 1000,
    ):
        self.target = target
        self.weight = weight
        self.steps = steps
        self.mask = mask
        self.max_t = start_fraction * num_steps

    def adjust_x0(self, x0: torch.Tensor, x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        if self.weight == 0 or float(t.max()) >= self.max_t:
            return x0
        # gradients are needed even under no_grad / inference_mode (Lightning's test and predict loops);
        # clones made outside inference mode are ordinary tensors that autograd may record
        with torch.inference_mode(False), torch.enable_grad():
            target = self.target.to(x0.device, x0.dtype).clone()
            mask = None if self.mask is None else self.mask.clone()
            x = x0.detach().clone()
            for _ in range(self.steps):
                x.requires_grad_(True)
                g = head_guidance_objective(x, target, mask).sum()
                (grad,) = torch.autograd.grad(g, x)
                x = (x - self.weight * grad).detach()
        return x


class HeadingGuidance(GuidanceTerm):
    """Turns x0_hat about the vertical so that its head faces the heading the video shows (ours).

    At every sampling step each frame's root orientation (and so the whole body, the head with it) is turned
    by ``weight`` times the gap between the target heading and the head's heading in x0_hat
    (:func:`.heading_frames.head_heading`): ``weight = 1`` sets every frame's heading to the target,
    smaller weights pull towards it. The root's position is left as sampled, so the body turns in place.
    The targets come from the egocentric video (:mod:`.video_rotation`), in the window's own frame.

    Args:
        target: (B, T) head headings (radians) in the motion's (canonical) frame.
        weight: fraction of the gap closed at each step, in (0, 1].
    """

    def __init__(self, target: torch.Tensor, weight: float = 1.0):
        if not 0 < weight <= 1:
            raise ValueError(f"the heading guidance weight must lie in (0, 1], got {weight}")
        self.target, self.weight = target, weight

    def adjust_x0(self, x0: torch.Tensor, x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        target = self.target.to(x0.device, x0.dtype)
        gap = torch.remainder(target - head_heading(head_rotation(x0)) + torch.pi, 2 * torch.pi) - torch.pi
        turn = yaw_matrices(self.weight * gap)[..., None, :, :]  # (B, T, 1, 3, 3)
        out = x0.clone()
        root = x0[..., ROOT_JOINT, :]
        for part in (slice(ROT.start, ROT.start + 3), slice(ROT.start + 3, ROT.stop)):
            out[..., ROOT_JOINT, part] = (turn[..., 0, :, :] @ root[..., part, None])[..., 0]
        return out
