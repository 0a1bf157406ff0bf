"""EMM training losses: the x0 reconstruction loss and the kinematic losses of [EgoMusic] supp. Eqs. 26-29.

All inputs are motion tokens (B, T, 24, 10) (:mod:`.representation`); FK maps them to joint positions.
Every squared norm is taken *per coordinate* (the mean over the coordinates it sums, EDGE's reduction in
``EDGE model/diffusion.py``), then averaged over frames and batch, so each term is on the scale of the
per-channel reconstruction loss and the lambdas alone weigh them:

- ``L_recon``: the x0 loss over the 151 data-carrying channels (:func:`reconstruction_loss`)
- ``L_pos = 1/T sum_i ||FK(x^i) - FK(x_hat^i)||^2 / 72`` (Eq. 26; 24 joints x 3, metres^2)
- ``L_vel = 1/(T-1) sum_i ||(x^{i+1} - x^i) - (x_hat^{i+1} - x_hat^i)||^2 / 147`` (Eq. 27) over the pose
  channels (rot6d + root; contacts excluded, as in EDGE)
- ``L_contact = 1/(T-1) sum_i ||(FK(x_hat^{i+1}) - FK(x_hat^i)) * b_hat^i||^2 / 12`` (Eq. 28) over the four
  foot joints, with ``b_hat^i`` the model's own contact prediction thresholded (EDGE: > 0.95)
- ``L_kin = lambda_pos L_pos + lambda_vel L_vel + lambda_contact L_contact`` (Eq. 29; weights unpublished)
- ``L_align``: the music-vision alignment loss (:func:`alignment_loss`; our interpretation, see there)

Why per coordinate: the paper writes plain squared norms, which sum 72 (positions) or 147 (velocities)
squared errors per frame against the reconstruction term's per-channel mean. Summed, the kinematic terms
outweighed the reconstruction 100 to 1 (L_pos about 47 m^2 against 0.08 at initialisation on the demo data),
and the demo's EMM, 200 Adam steps on two 48-frame windows, fitted x0 at t = 1 20 times worse than with the
reconstruction alone (MSE 0.26 against 0.013).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from skeleton_mamba.tasks.egodance.representation import (
    CONTACT,
    FOOT_JOINTS,
    channel_mask,
    decode_motion,
    motion_joints,
)

__all__ = [
    "KinematicLossWeights",
    "reconstruction_loss",
    "position_loss",
    "velocity_loss",
    "contact_loss",
    "alignment_loss",
    "emm_losses",
]


@dataclass
class KinematicLossWeights:
    """lambda of Eq. 29 (unpublished; defaults: the authors' rewrite's guesses pos 1, vel 0.1, contact 1)."""

    pos: float = 1.0
    vel: float = 0.1
    contact: float = 1.0


def _frame_sq_norm(diff: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """(B, T, J, C) -> (B, T) squared norm per frame divided by its coordinate count (weighted: by the
    weights' sum), i.e. the mean squared error per coordinate."""
    sq = diff.pow(2)
    if weight is None:
        return sq.flatten(2).mean(-1)
    return (sq * weight).flatten(2).sum(-1) / weight.sum()


def reconstruction_loss(x0_hat: torch.Tensor, x0: torch.Tensor, kind: str = "l2") -> torch.Tensor:
    """x0 loss over the data-carrying channels: squared (EDGE) or absolute (original code) error."""
    w = channel_mask(x0.dtype, x0.device)
    err = (x0_hat - x0) * w
    per = err.pow(2) if kind == "l2" else err.abs() if kind == "l1" else None
    if per is None:
        raise ValueError(f"unknown reconstruction loss {kind!r} (l1 | l2)")
    return per.sum() / (w.sum() * x0.shape[0] * x0.shape[1])


def position_loss(
    x0_hat: torch.Tensor, x0: torch.Tensor, joints_hat: torch.Tensor | None = None
) -> torch.Tensor:
    """Eq. 26 (FK positions, metres^2 per coordinate); ``joints_hat``: FK(x0_hat) when already computed."""
    joints_hat = motion_joints(x0_hat) if joints_hat is None else joints_hat
    return _frame_sq_norm(motion_joints(x0) - joints_hat).mean()


def velocity_loss(x0_hat: torch.Tensor, x0: torch.Tensor) -> torch.Tensor:
    """Eq. 27 on the pose channels (contacts excluded)."""
    w = channel_mask(x0.dtype, x0.device)
    w[:, CONTACT] = 0
    d = (x0[:, 1:] - x0[:, :-1]) - (x0_hat[:, 1:] - x0_hat[:, :-1])
    return _frame_sq_norm(d, w).mean()


def contact_loss(
    x0_hat: torch.Tensor, threshold: float = 0.95, joints_hat: torch.Tensor | None = None
) -> torch.Tensor:
    """Eq. 28: foot velocity of the prediction where its own contact prediction exceeds ``threshold``;
    ``joints_hat``: FK(x0_hat) when already computed."""
    _, _, contacts = decode_motion(x0_hat)
    b = (contacts[:, :-1] > threshold).to(x0_hat.dtype)  # (B, T-1, 4), b_hat^i
    joints_hat = motion_joints(x0_hat) if joints_hat is None else joints_hat
    feet = joints_hat[..., list(FOOT_JOINTS), :]
    vel = (feet[:, 1:] - feet[:, :-1]) * b[..., None]
    return _frame_sq_norm(vel).mean()


def alignment_loss(z_a: torch.Tensor, z_v: torch.Tensor, temperature: float = 0.07) -> torch.Tensor:
    """Music-vision alignment loss, a symmetric InfoNCE over time steps (OUR INTERPRETATION).

    [EgoMusic] supp. Sec. 6.3 adds "an alignment loss as proposed in our method to improve the
    consistency between the modalities" to every baseline and calls the fused embeddings "aligned", but
    defines the loss only in the (unavailable) main paper. We read it as a contrastive (CLIP / InfoNCE)
    alignment of the music embedding z_a and the vision embedding z_v *per time step*: the music and
    vision tokens of the same frame of the same window are a positive pair, every other frame of the batch
    is a negative::

        a_i = z_a,i / ||z_a,i||,  v_j = z_v,j / ||z_v,j||,  s_ij = <a_i, v_j> / tau   (i, j over B*T tokens)
        L_align = 1/2 [ -1/N sum_i log softmax_j(s_ij)[i] - 1/N sum_j log softmax_i(s_ij)[j] ]

    Args:
        z_a: (B, T, Dc) music embeddings (music encoder output).
        z_v: (B, T, Dc) vision embeddings (vision encoder output).
        temperature: tau (CLIP's initial value 0.07).

    Returns:
        The scalar loss.
    """
    if z_a.shape != z_v.shape:
        raise ValueError(f"music {tuple(z_a.shape)} and vision {tuple(z_v.shape)} embeddings differ in shape")
    a = F.normalize(z_a.flatten(0, -2), dim=-1)
    v = F.normalize(z_v.flatten(0, -2), dim=-1)
    logits = a @ v.T / temperature  # (N, N), N = B * T
    target = torch.arange(logits.shape[0], device=logits.device)
    return 0.5 * (F.cross_entropy(logits, target) + F.cross_entropy(logits.T, target))


def emm_losses(
    x0_hat: torch.Tensor,
    x0: torch.Tensor,
    weights: KinematicLossWeights | None = None,
    reconstruction: str = "l2",
    contact_threshold: float = 0.95,
) -> dict[str, torch.Tensor]:
    """All terms: ``recon``, ``pos``, ``vel``, ``contact``, ``kin`` (Eq. 29) and ``loss = recon + kin``."""
    weights = weights or KinematicLossWeights()
    joints_hat = motion_joints(x0_hat)  # FK of the prediction once, for L_pos and L_contact
    out = {
        "recon": reconstruction_loss(x0_hat, x0, reconstruction),
        "pos": position_loss(x0_hat, x0, joints_hat),
        "vel": velocity_loss(x0_hat, x0),
        "contact": contact_loss(x0_hat, contact_threshold, joints_hat),
    }
    out["kin"] = weights.pos * out["pos"] + weights.vel * out["vel"] + weights.contact * out["contact"]
    out["loss"] = out["recon"] + out["kin"]
    return out
