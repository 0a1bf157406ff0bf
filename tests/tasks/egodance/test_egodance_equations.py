"""EMM equations against independent computations: the x0 training target, the timestep conditioning of the
denoiser, the head guidance G_head (target joint and step), and the fusion of vision and music."""

import math
import warnings

import numpy as np
import torch

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.egodance.encoders import FusionModule
from skeleton_mamba.tasks.egodance.guidance import HeadGuidance, head_guidance_objective
from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
from skeleton_mamba.tasks.egodance.representation import encode_motion
from skeleton_mamba.tasks.motion.body.smpl import SMPL_REST_OFFSETS
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, sinusoidal_embedding

PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]


def _rest_offset(joint: int) -> np.ndarray:
    """Rest-pose position of ``joint`` relative to the root, summed along its parent chain by hand."""
    off, pos = np.asarray(SMPL_REST_OFFSETS), np.zeros(3)
    while joint > 0:
        pos, joint = pos + off[joint], PARENTS[joint]
    return pos


def _rest_tokens(root: torch.Tensor) -> torch.Tensor:
    """(1, T, 24, 10) rest-pose tokens (identity rotations) at root positions (T, 3)."""
    x = torch.zeros(1, root.shape[0], 24, 10, dtype=torch.float64)
    x[..., :6] = torch.tensor([1.0, 0.0, 0.0, 0.0, 1.0, 0.0], dtype=torch.float64)
    x[0, :, 0, 6:9] = root
    return x


def _tiny_emm() -> EMM:
    backbone = SkeletonMambaConfig(
        dim=16, depth=1, mlp_dim=32, heads=2, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    resnet = dict(embedding_size=8, hidden_sizes=[8, 16], depths=[1, 1], layer_type="basic")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        network = EMMConfig(context_dim=16, resnet_layers=resnet, heads=2, transformer_ff=32)
        return EMM(backbone, network, image_size=32)


# ---------------------------------------------------------------------------------------- x0 target
def test_training_pair_is_q_sample_with_the_clean_motion_as_target():
    num_steps, s = 50, 0.008
    diffusion = GaussianDiffusion(num_steps)
    x0, noise = torch.randn(3, 6, 24, 10, dtype=torch.float64), torch.randn(3, 6, 24, 10, dtype=torch.float64)
    t = torch.tensor([0, 17, 49])
    x_t, t_out, target = diffusion.training_pair(x0, t, noise)

    # cosine schedule by hand (Nichol & Dhariwal; EDGE): betas clipped at 0.999, alpha_bar = prod (1 - beta)
    def f(u: float) -> float:
        return math.cos((u / num_steps + s) / (1 + s) * math.pi / 2) ** 2

    betas = [min(1 - f(i + 1) / f(i), 0.999) for i in range(num_steps)]
    abar = np.cumprod([1 - b for b in betas])
    for i, step in enumerate(t.tolist()):
        expected = math.sqrt(abar[step]) * x0[i] + math.sqrt(1 - abar[step]) * noise[i]
        torch.testing.assert_close(x_t[i], expected, rtol=1e-5, atol=1e-6)
    assert torch.equal(t_out, t)
    assert torch.equal(target, x0)  # x0 prediction, not the noise


def test_module_trains_the_denoiser_towards_the_clean_motion(tiny_egodance_module):
    torch.manual_seed(0)
    module = tiny_egodance_module(cond_drop_prob=0.0, lambda_align=0.0)
    joints = encode_motion(0.1 * torch.randn(2, 8, 24, 3), 0.1 * torch.randn(2, 8, 3))
    batch = {"motion": joints, "music": torch.randn(2, 8, 35), "frames": torch.rand(2, 8, 3, 32, 32)}
    seen = {}

    def oracle_denoiser(x_t, t, context=None, mask=None):  # returns the clean motion exactly
        seen["x_t"], seen["t"] = x_t, t
        return batch["motion"].clone()

    module.model.forward = oracle_denoiser
    losses = module._losses(batch, torch.Generator().manual_seed(0))
    # a perfect x0 prediction has zero reconstruction, position and velocity loss; a noise target would not
    for key in ("recon", "pos", "vel"):
        assert losses[key].item() < 1e-10, key
    assert not torch.allclose(seen["x_t"], batch["motion"])  # the denoiser saw a noised input


# --------------------------------------------------------------------------------- timestep conditioning
def test_sinusoidal_embedding_by_hand():
    t, dim = torch.tensor([0, 3, 999]), 8
    emb = sinusoidal_embedding(t, dim)
    for i, step in enumerate(t.tolist()):
        freqs = [10000 ** (-k / 4) for k in range(4)]
        expected = [math.sin(step * f) for f in freqs] + [math.cos(step * f) for f in freqs]
        np.testing.assert_allclose(emb[i].numpy(), expected, rtol=1e-5, atol=1e-5)


def test_emm_denoiser_is_conditioned_on_the_timestep():
    torch.manual_seed(0)
    model = _tiny_emm().eval()
    x_t, context = torch.randn(2, 8, 24, 10), torch.randn(2, 8, 16)
    t = torch.tensor([3, 700])
    with torch.no_grad():
        out = model(x_t, t, context)
        # the forward pass by hand: the time embedding is added to every joint token and prepended to the
        # condition as a cross-attention token, inside the x0 preconditioning (tested on its own in
        # test_demo_scores: scaled input, skip connection from x_t)
        temb = model.time_mlp(sinusoidal_embedding(t, 16))
        h = model.input_proj(model.skip_x0.network_input(x_t, t)) + temb[:, None, None, :]
        inner = model.backbone(h, context=torch.cat([model.time_token(temb)[:, None], context], dim=1))
        by_hand = model.skip_x0(x_t, inner, t)
        other_t = model(x_t, torch.tensor([500, 10]), context)
    torch.testing.assert_close(out, by_hand)
    assert (out - other_t).abs().amax(dim=(1, 2, 3)).min() > 1e-4  # each sample's output depends on its t


# ---------------------------------------------------------------------------------------- head guidance
def test_head_guidance_objective_and_step_target_the_head_joint():
    root = torch.tensor([[0.0, 0.9, 0.0], [0.1, 0.95, -0.2], [0.3, 0.9, 0.1]], dtype=torch.float64)
    x0 = _rest_tokens(root)
    head = root + torch.from_numpy(_rest_offset(15))  # SMPL joint 15 "head" (12 is the neck)
    target = head + torch.tensor([[0.2, -0.1, 0.05], [0.0, 0.3, 0.0], [-0.1, 0.0, 0.2]], dtype=torch.float64)
    mask = torch.tensor([[True, True, False]])

    # G_head = sum over valid frames of ||p_15 - p*||^2
    expected = ((head - target) ** 2).sum(-1)[:2].sum()
    torch.testing.assert_close(head_guidance_objective(x0, target[None], mask)[0], expected)
    assert np.linalg.norm(_rest_offset(15) - _rest_offset(12)) > 0.05  # the neck would give another value

    # one step x0 <- x0 - w grad G: the root moves by -2 w (p_15 - p*) (d p_15 / d root = I); masked: kept
    w = 0.05
    guided = HeadGuidance(target[None], weight=w, steps=1, mask=mask, num_steps=10).adjust_x0(
        x0, x0, torch.tensor([3])
    )
    expected_root = root - 2 * w * (head - target)
    torch.testing.assert_close(guided[0, :2, 0, 6:9], expected_root[:2])
    torch.testing.assert_close(guided[0, 2], x0[0, 2])


# ---------------------------------------------------------------------------------------- fusion
def test_fusion_module_by_hand():
    torch.manual_seed(0)
    fusion = FusionModule(dim=16, layers=1, heads=2, ff_dim=32, dropout=0.0).eval()
    music, vision = torch.randn(2, 5, 16), torch.randn(2, 5, 16)
    with torch.no_grad():
        out = fusion(music, vision)
        pos = sinusoidal_embedding(torch.arange(5), 16)
        tokens = torch.cat([music + pos + fusion.modality[0], vision + pos + fusion.modality[1]], dim=1)
        mixed = fusion.encoder(tokens)
        by_hand = 0.5 * (mixed[:, :5] + mixed[:, 5:])  # the two tokens of each frame averaged
        other_vision = fusion(music, torch.randn(2, 5, 16))
        other_music = fusion(torch.randn(2, 5, 16), vision)
    torch.testing.assert_close(out, by_hand)
    assert (out - other_vision).abs().max() > 1e-3 and (out - other_music).abs().max() > 1e-3


def test_emm_condition_fuses_encoded_music_and_vision():
    torch.manual_seed(0)
    model = _tiny_emm().eval()
    music, frames = torch.randn(2, 6, 35), torch.rand(2, 6, 3, 32, 32)
    with torch.no_grad():
        condition = model.encode_condition(music, frames)
        by_hand = model.fusion(model.music_encoder(music), model.vision_encoder(frames))
        without_video = model.encode_condition(music, torch.rand(2, 6, 3, 32, 32))
    torch.testing.assert_close(condition, by_hand)
    assert (condition - without_video).abs().max() > 1e-4  # the frames reach the condition
