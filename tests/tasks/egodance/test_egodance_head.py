"""Head trajectory from the video (estimator, loss, errors, training beside the EMM), the pretrained vision
encoder's loading, the recipes of the paper's protocol and of our fast variant, parameter counts."""

from __future__ import annotations

import dataclasses
import inspect
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from scipy.spatial.transform import Rotation
from transformers import ResNetConfig, ResNetModel

from skeleton_mamba import SkeletonMambaConfig
from skeleton_mamba.tasks.egodance.builder.camera import head_camera
from skeleton_mamba.tasks.egodance.encoders import load_resnet
from skeleton_mamba.tasks.egodance.guidance import head_pose_from_camera
from skeleton_mamba.tasks.egodance.head_estimator import (
    HeadEstimatorConfig,
    HeadTrajectoryEstimator,
    estimate_long_trajectory,
    head_trajectory_errors,
    head_trajectory_loss,
)
from skeleton_mamba.tasks.egodance.module import EgoDanceModule
from skeleton_mamba.tasks.egodance.representation import encode_motion
from tests.helpers.precision_cases import TRAINING_PRECISIONS, forward_context

RECIPES = Path(__file__).resolve().parents[3] / "recipes"
TINY = HeadEstimatorConfig(input_size=16, channels=(8, 8), dim=8, layers=1)


def test_head_pose_inverts_the_builder_camera():
    heads = np.random.default_rng(0).normal(size=(4, 3))
    rots = Rotation.random(4, random_state=1).as_matrix()
    cam = head_camera(heads, rots, np.eye(3), 32, 24, forward_offset=0.1, up_offset=0.06)
    positions, rotations = head_pose_from_camera(cam.positions, cam.rotations, 0.1, 0.06)
    np.testing.assert_allclose(positions, heads, atol=1e-12)
    np.testing.assert_allclose(rotations, rots, atol=1e-12)  # the head joint's rotation, not the camera's


def test_estimator_outputs_positions_and_gram_schmidt_rotations():
    net = HeadTrajectoryEstimator(TINY)
    rot6d = torch.tensor([0.8, 0.6, 0.0, 0.0, 0.0, 1.0])
    with torch.no_grad():  # constant outputs: position (0.1, 1.5, -0.2) and a fixed rotation
        net.head.weight.zero_()
        net.head.bias.copy_(torch.cat([torch.tensor([0.1, 1.5, -0.2]), rot6d]))
        positions, rotations = net(torch.rand(2, 6, 3, 20, 20))
    torch.testing.assert_close(positions, torch.tensor([0.1, 1.5, -0.2]).expand(2, 6, 3))
    columns = torch.tensor([[0.8, 0.0, 0.6], [0.6, 0.0, -0.8], [0.0, 1.0, 0.0]])  # Gram-Schmidt by hand
    torch.testing.assert_close(rotations, columns.expand(2, 6, 3, 3))


def test_long_videos_are_estimated_window_by_window_and_chained():
    class WindowRelative(torch.nn.Module):  # a perfect estimator: each window starts at x = z = 0.1
        def forward(self, frames):
            xz = frames[..., 0, :2, 0] - frames[:, :1, 0, :2, 0] + 0.1
            pos = torch.stack([xz[..., 0], torch.full_like(xz[..., 0], 1.6), xz[..., 1]], dim=-1)
            return pos, torch.eye(3).expand(*pos.shape[:2], 3, 3)

    path = torch.cumsum(torch.randn(25, 2, generator=torch.Generator().manual_seed(0)), dim=0)
    frames = torch.zeros(25, 3, 4, 4)
    frames[:, 0, :2, 0] = path  # the frames "show" the true horizontal position
    positions, rotations = estimate_long_trajectory(WindowRelative(), frames, window=10)  # windows 0, 9, 15
    expected = torch.stack(
        [path[:, 0] - path[0, 0] + 0.1, torch.full((25,), 1.6), path[:, 1] - path[0, 1] + 0.1], -1
    )
    torch.testing.assert_close(positions, expected)
    assert rotations.shape == (25, 3, 3)
    short, _ = estimate_long_trajectory(WindowRelative(), frames[:8], window=10)
    torch.testing.assert_close(short, expected[:8])


def test_loss_and_errors_by_hand():
    true_pos = torch.zeros(1, 2, 3)
    pos = torch.tensor([[[0.03, 0.04, 0.0], [0.0, 0.0, 0.1]]])  # 50 mm and 100 mm off
    true_rot = torch.eye(3).expand(1, 2, 3, 3)
    rot = torch.from_numpy(Rotation.from_euler("y", [[30], [90]], degrees=True).as_matrix()).float()[None]
    pos_err, rot_err = head_trajectory_errors(pos, rot, true_pos, true_rot)
    torch.testing.assert_close(pos_err, torch.tensor([75.0]))
    torch.testing.assert_close(rot_err, torch.tensor([60.0]))
    # loss: mean squared distance in units of 0.1 m + w * mean squared chordal distance (4 - 4 cos angle)
    chordal = np.mean([4 - 4 * math.cos(math.radians(a)) for a in (30, 90)])
    expected = (0.5**2 + 1.0**2) / 2 + 0.5 * chordal
    got = head_trajectory_loss(pos, rot, true_pos, true_rot, rotation_weight=0.5, position_scale=0.1)
    assert got.item() == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("precision", TRAINING_PRECISIONS)
def test_estimator_learns_height_and_turn_from_frames(precision):
    # toy videos: brightness encodes the head height, a moving bar the yaw; 80 Adam steps must beat the mean
    gen = torch.Generator().manual_seed(0)
    heights = 1.4 + 0.4 * torch.rand(16, 1, generator=gen)
    frames = heights[..., None, None, None].expand(16, 6, 3, 16, 16) - 1.2
    yaw = torch.linspace(0, 0.5, 6) * torch.randn(16, 1, generator=gen).sign()
    frames = frames.clone()
    for b in range(16):
        for t in range(6):
            frames[b, t, :, :, int(8 + 14 * yaw[b, t]) % 16] = 1.0
    rot = (
        torch.from_numpy(Rotation.from_euler("y", yaw.reshape(-1, 1).numpy()).as_matrix())
        .float()
        .reshape(16, 6, 3, 3)
    )
    pos = torch.zeros(16, 6, 3)
    pos[..., 1] = heights
    torch.manual_seed(0)
    net = HeadTrajectoryEstimator(TINY)
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)
    for _ in range(80):
        with forward_context(precision):
            loss = head_trajectory_loss(*(t.float() for t in net(frames)), pos, rot)
        assert torch.isfinite(loss)
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        pos_err, _ = head_trajectory_errors(*net(frames), pos, rot)
    baseline, _ = head_trajectory_errors(pos.mean(0, keepdim=True).expand_as(pos), rot, pos, rot)
    assert pos_err.mean() < 0.5 * baseline.mean()


def test_estimator_training_leaves_the_emm_gradients_unchanged(tiny_egodance_module):
    torch.manual_seed(0)
    module = tiny_egodance_module(cond_drop_prob=0.0)
    batch = {
        "motion": encode_motion(0.1 * torch.randn(2, 8, 24, 3), 0.1 * torch.randn(2, 8, 3)),
        "music": torch.randn(2, 8, 35),
        "frames": torch.rand(2, 8, 3, 32, 32),
        "head": torch.randn(2, 8, 3),
        "head_rotation": torch.eye(3).expand(2, 8, 3, 3),
    }
    module.eval()  # no dropout: the two passes see the same network
    grads = []
    for with_estimator in (False, True):
        module.zero_grad()
        loss = module._losses(batch, torch.Generator().manual_seed(1))["loss"]
        if with_estimator:
            loss = loss + module._head_estimator_loss(batch)
        loss.backward()
        grads.append([p.grad.clone() for p in module.model.parameters() if p.grad is not None])
    assert len(grads[0]) == len(grads[1]) > 0
    for a, b in zip(*grads, strict=True):
        torch.testing.assert_close(a, b)
    assert all(p.grad is not None for p in module.head_estimator.parameters())
    # separate gradient clipping: a huge estimator gradient does not shrink the EMM's
    emm_before = [p.grad.clone() for p in module.model.parameters() if p.grad is not None]
    for p in module.head_estimator.parameters():
        p.grad.mul_(1e6)
    norm = torch.linalg.vector_norm(torch.stack([g.norm() for g in emm_before]))
    module.configure_gradient_clipping(
        None, gradient_clip_val=float(norm) * 2, gradient_clip_algorithm="norm"
    )
    for a, p in zip(emm_before, [p for p in module.model.parameters() if p.grad is not None], strict=True):
        torch.testing.assert_close(a, p.grad)
    est = torch.linalg.vector_norm(torch.stack([p.grad.norm() for p in module.head_estimator.parameters()]))
    assert est.item() == pytest.approx(float(norm) * 2, rel=1e-4)


def test_head_sources_and_their_errors(tiny_egodance_module):
    with pytest.raises(ValueError, match="head_source"):
        tiny_egodance_module(head_source="camera")
    with pytest.raises(ValueError, match="needs egocentric frames"):
        tiny_egodance_module(use_vision=False)
    module = tiny_egodance_module(use_vision=False, head_source="none")
    assert module.head_estimator is None and module.head_targets({"music": torch.zeros(1, 4, 35)}) is None
    module = tiny_egodance_module(head_source="oracle")
    with pytest.raises(ValueError, match="ground-truth head"):
        module.head_targets({"music": torch.zeros(1, 4, 35)})
    module = tiny_egodance_module()
    frames = torch.rand(1, 4, 3, 32, 32)
    estimate = module.head_targets({"frames": frames, "head": torch.zeros(1, 4, 3)})
    torch.testing.assert_close(estimate, module.head_estimator.eval()(frames)[0])


def test_parameter_counts(tiny_egodance_module):
    module = tiny_egodance_module(freeze_resnet=True)
    counts = module.parameter_counts()
    resnet = sum(p.numel() for p in module.model.vision_encoder.resnet.parameters())
    assert counts["emm_frozen"] == resnet > 0
    assert counts["emm_trainable"] + counts["emm_frozen"] == sum(p.numel() for p in module.model.parameters())
    assert counts["head_estimator"] == sum(p.numel() for p in module.head_estimator.parameters()) > 0


# ---------------------------------------------------------------------------------------- vision encoder
def _tiny_resnet() -> ResNetModel:
    torch.manual_seed(0)
    config = ResNetConfig(embedding_size=8, hidden_sizes=[8, 16], depths=[1, 1], layer_type="basic")
    return ResNetModel(config)


def test_resnet_loads_from_a_local_folder(tmp_path):
    model = _tiny_resnet()
    model.save_pretrained(tmp_path / "resnet")
    loaded = load_resnet(str(tmp_path / "resnet"))
    for (name, a), (_, b) in zip(model.state_dict().items(), loaded.state_dict().items(), strict=True):
        assert torch.equal(a, b), name
    with pytest.raises(FileNotFoundError, match="not a folder"):
        load_resnet(str(tmp_path / "missing" / "resnet"))


def test_offline_uncached_resnet_stops_with_one_clear_message(monkeypatch):
    import huggingface_hub.constants

    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)
    with pytest.raises(OSError) as info:
        load_resnet("skeleton-mamba-tests/no-such-resnet")
    message = str(info.value)
    assert "skeleton-mamba-tests/no-such-resnet" in message
    assert "save_pretrained" in message and "--model.init_args.resnet_path resnet-50" in message
    assert "--model.init_args.resnet_path null" in message  # the explicit random encoder


# ---------------------------------------------------------------------------------------- recipes
def _model_args(name: str) -> dict:
    """The recipe's model arguments over EgoDanceModule's defaults: the ``network`` (EMMConfig) fields among
    them, a config group's fields as ``group.field``."""
    args = yaml.safe_load((RECIPES / name).read_text())["model"]["init_args"]
    out = {**args.pop("network")}
    for key, parameter in inspect.signature(EgoDanceModule).parameters.items():
        if dataclasses.is_dataclass(parameter.default):
            given = args.pop(key, None) or {}
            out.update({f"{key}.{k}": v for k, v in {**asdict(parameter.default), **given}.items()})
        elif key != "network":
            out[key] = args.pop(key, parameter.default)
    assert not args, f"{name}: unknown model arguments {sorted(args)}"
    return out


def test_egodance_recipe_is_the_papers_protocol():
    paper = _model_args("egodance.yaml")
    # the backbone file states only what differs from SkeletonMambaConfig's defaults ([EgoMusic]'s sizes)
    backbone = {**asdict(SkeletonMambaConfig()), **yaml.safe_load((RECIPES / paper["backbone"]).read_text())}
    assert (backbone["dim"], backbone["depth"], backbone["heads"], backbone["mlp_dim"]) == (128, 8, 4, 1024)
    assert (paper["context_dim"], paper["heads"], paper["transformer_ff"]) == (256, 4, 512)
    assert paper["encoder_layers"] == paper["fusion_layers"] == 2
    assert (paper["diffusion_steps"], paper["sampling.sampler"]) == (1000, "ddpm")
    assert paper["loss.cond_drop_prob"] == 0.0 and paper["sampling.guidance_weight"] == 1.0  # no CFG
    assert (paper["optimizer.lr"], paper["resnet_path"]) == (0.0002, "microsoft/resnet-50")
    assert paper["head_guidance.source"] == "estimate" and paper["head_guidance.test_oracle"] is True
    overlay = yaml.safe_load((RECIPES / "egodance_fast.yaml").read_text())
    assert overlay["base"] == "egodance.yaml"  # the merged result: tests/training/test_cli.py
    fast = overlay["model"]["init_args"]
    assert fast["sampling"] == {"sampler": "ddim", "sampling_steps": 50, "guidance_weight": 2.0}
    assert fast["loss"] == {"cond_drop_prob": 0.25}
    assert set(fast) == {"sampling", "loss"} and set(overlay["model"]) == {"init_args"}  # sampling only
    assert set(overlay) == {"base", "trainer", "model"} and set(overlay["trainer"]) == {"logger"}
    header = (RECIPES / "egodance_fast.yaml").read_text().splitlines()[0]
    assert "THIS PROJECT'S" in header
