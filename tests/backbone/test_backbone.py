"""The SkeletonMamba backbone: shapes, parameter counts, padding, conditioning and learning."""

import dataclasses

import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.skeletons import SKELETONS
from tests.helpers.precision_cases import TRAINING_PRECISIONS, forward_context

TINY_MIXER = MixerConfig(d_state=8, headdim=8, chunk_size=16)


def _mixer_params(d_model, cfg):
    d_inner = cfg.expand * d_model
    heads = d_inner // cfg.headdim
    conv = d_inner + 2 * cfg.ngroups * cfg.d_state
    in_proj = d_model * (2 * d_inner + 2 * cfg.ngroups * cfg.d_state + heads)
    return in_proj + conv * cfg.d_conv + conv + 3 * heads + d_inner + d_inner * d_model


def _expected_params(cfg: SkeletonMambaConfig, num_joints: int, group_size: int) -> int:
    """Parameter count from the architecture's description, summed by hand."""
    mixer = cfg.mixer or MixerConfig()
    d, e = cfg.dim, group_size * cfg.dim
    ln = lambda w: 2 * w  # noqa: E731
    lin = lambda i, o: i * o + o  # noqa: E731
    block = (
        ln(d)
        + _mixer_params(e, mixer)  # norm before the tokenizer, group scan
        + ln(e)
        + lin(e, e)
        + _mixer_params(d, mixer)  # norm, Linear E->P*D, joint scan
        + ln(d)
        + 2 * _mixer_params(d, mixer)
        + lin(d, d)  # temporal scan: two directions + Linear
        + ln(d)
        + lin(d, cfg.mlp_dim)
        + lin(cfg.mlp_dim, d)  # MLP
    )
    if cfg.context_dim is not None:
        block += ln(d) + d * d + cfg.context_dim * 2 * d + lin(d, d)
    total = cfg.depth * block + ln(d)
    total += lin(cfg.in_channels, d) if cfg.in_channels else 0
    total += lin(d, cfg.out_channels) if cfg.out_channels else 0
    total += num_joints * d if cfg.joint_embedding else 0
    return total


@pytest.mark.parametrize("name", sorted(SKELETONS))
def test_output_shape_and_parameter_count_for_each_skeleton(name):
    sk = SKELETONS[name]
    cfg = SkeletonMambaConfig(
        skeleton=name,
        in_channels=3,
        out_channels=5,
        dim=16,
        depth=2,
        mlp_dim=32,
        context_dim=12,
        mixer=TINY_MIXER,
    )
    model = SkeletonMamba(cfg)
    y = model(torch.randn(2, 9, sk.num_joints, 3), context=torch.randn(2, 4, 12))
    assert y.shape == (2, 9, sk.num_joints, 5)
    assert sum(p.numel() for p in model.parameters()) == _expected_params(cfg, sk.num_joints, sk.group_size)


def test_paper_configuration_parameter_count():
    cfg = SkeletonMambaConfig()  # D 128, G 5, P 6, E 768, N 8, MLP 1024 ([EgoMusic] supp. Table 2)
    model = SkeletonMamba(cfg)
    n = sum(p.numel() for p in model.parameters())
    assert n == _expected_params(cfg, 24, 6)
    assert 30e6 < n < 47.4e6  # the whole EMM (with encoders) has 47.4 M


def test_padded_frames_never_change_valid_outputs():
    torch.manual_seed(0)
    cfg = SkeletonMambaConfig(skeleton="ntu25", in_channels=3, dim=16, depth=2, mlp_dim=32, mixer=TINY_MIXER)
    model = SkeletonMamba(cfg).eval()
    lengths = torch.tensor([30, 17])
    x = torch.randn(2, 30, 25, 3)
    mask = torch.arange(30)[None] < lengths[:, None]
    noisy = x.clone()
    noisy[1, 17:] = 100 * torch.randn(13, 25, 3)
    a, b = model(x, mask), model(noisy, mask)
    alone = model(x[1:, :17])
    torch.testing.assert_close(a[1, :17], alone[0], rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(b[1, :17], alone[0], rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(a[0], model(x[:1])[0], rtol=1e-4, atol=1e-5)


def test_context_mask_hides_padded_condition_tokens():
    torch.manual_seed(0)
    cfg = SkeletonMambaConfig(in_channels=3, dim=16, depth=1, mlp_dim=32, context_dim=8, mixer=TINY_MIXER)
    model = SkeletonMamba(cfg).eval()
    x, ctx = torch.randn(1, 6, 24, 3), torch.randn(1, 5, 8)
    cmask = torch.tensor([[True, True, True, False, False]])
    other = ctx.clone()
    other[:, 3:] = torch.randn(1, 2, 8)
    torch.testing.assert_close(
        model(x, context=ctx, context_mask=cmask), model(x, context=other, context_mask=cmask)
    )
    torch.testing.assert_close(model(x, context=ctx, context_mask=cmask), model(x, context=ctx[:, :3]))
    assert not torch.allclose(model(x, context=ctx), model(x, context=other))


def test_bad_inputs_are_explained():
    model = SkeletonMamba(SkeletonMambaConfig(in_channels=3, dim=16, depth=1, mlp_dim=16, mixer=TINY_MIXER))
    with pytest.raises(ValueError, match="smpl24"):
        model(torch.randn(1, 4, 25, 3))
    with pytest.raises(ValueError, match="prefix"):
        model(torch.randn(1, 3, 24, 3), torch.tensor([[True, False, True]]))
    with pytest.raises(TypeError):
        SkeletonMamba(SkeletonMambaConfig(), dim=3)
    assert dataclasses.replace(SkeletonMambaConfig(), skeleton="ntu25").skeleton == "ntu25"


@pytest.mark.parametrize("precision", TRAINING_PRECISIONS)
def test_tiny_model_learns_a_sequence_task(precision):
    """Predict, per joint, the running mean of a signal up to each frame and the global mean:
    needs both temporal directions and the joint mixing of the group/joint scans (also in bf16-mixed)."""
    torch.manual_seed(0)
    cfg = SkeletonMambaConfig(
        skeleton="humanml3d22",
        in_channels=1,
        out_channels=2,
        dim=16,
        depth=1,
        mlp_dim=32,
        mixer=MixerConfig(d_state=8, headdim=16, chunk_size=16),
    )
    model = SkeletonMamba(cfg)
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3)

    def batch():
        x = torch.randn(8, 16, 22, 1)
        run = x.cumsum(1) / torch.arange(1, 17).view(1, 16, 1, 1)
        glob = x.mean(dim=(1, 2), keepdim=True).expand_as(x)
        return x, torch.cat([run, glob], -1)

    losses = []
    for _ in range(60):
        x, target = batch()
        with forward_context(precision):
            loss = torch.nn.functional.mse_loss(model(x).float(), target)
        assert torch.isfinite(loss)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    start, end = sum(losses[:5]) / 5, sum(losses[-10:]) / 10
    assert end < 0.25 * start, (start, end)


def test_gradient_checkpointing_gives_the_same_gradients():
    torch.manual_seed(0)
    cfg = SkeletonMambaConfig(in_channels=3, dim=16, depth=2, mlp_dim=16, mixer=TINY_MIXER)
    plain = SkeletonMamba(cfg)
    ckpt = SkeletonMamba(dataclasses.replace(cfg, gradient_checkpointing=True))
    ckpt.load_state_dict(plain.state_dict())
    x = torch.randn(2, 7, 24, 3)
    grads = []
    for model in (plain, ckpt):
        model(x).square().mean().backward()
        grads.append(torch.cat([p.grad.flatten() for p in model.parameters()]))
    torch.testing.assert_close(grads[0], grads[1])
