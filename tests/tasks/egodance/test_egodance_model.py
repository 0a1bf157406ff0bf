"""EMM: motion representation, losses (Eqs. 26-29) by hand, head guidance, one training step."""

import warnings

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.tasks.egodance.builder.camera import head_camera
from skeleton_mamba.tasks.egodance.guidance import (
    HeadGuidance,
    head_guidance_objective,
    head_targets_from_camera,
)
from skeleton_mamba.tasks.egodance.losses import (
    contact_loss,
    emm_losses,
    position_loss,
    reconstruction_loss,
    velocity_loss,
)
from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
from skeleton_mamba.tasks.egodance.representation import decode_motion, encode_motion, motion_joints
from skeleton_mamba.tasks.motion.body.smpl import SMPL_REST_OFFSETS
from skeleton_mamba.tasks.training.diffusion import GaussianDiffusion, ddim_sample

IDENTITY_6D = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]  # first two columns of the identity


def _rest_motion(t: int, root: torch.Tensor | None = None) -> torch.Tensor:
    """(1, T, 24, 10) tokens of the rest pose (identity rotations) at the given root positions (T, 3)."""
    x = torch.zeros(1, t, 24, 10, dtype=torch.float64)
    x[..., :6] = torch.tensor(IDENTITY_6D, dtype=torch.float64)
    if root is not None:
        x[0, :, 0, 6:9] = root
    return x


def _rest_joints() -> np.ndarray:
    """Rest-pose joint positions by summing offsets along the parent chain (independent of the FK code)."""
    parents = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]
    off = np.asarray(SMPL_REST_OFFSETS)
    pos = np.zeros((24, 3))
    for j in range(1, 24):
        pos[j] = pos[parents[j]] + off[j]
    return pos


def test_representation_round_trip_and_contacts():
    rng = np.random.default_rng(0)
    t = 6
    poses = torch.from_numpy(rng.normal(scale=0.4, size=(t, 24, 3)))
    root = torch.zeros(t, 3, dtype=torch.float64)
    root[3:, 0] = (
        torch.arange(1, t - 2, dtype=torch.float64) * 0.05
    )  # still for 4 frames, then 5 cm per frame
    poses[:, 1:] = poses[0, 1:]  # only the root orientation could move the feet: keep it fixed as well
    poses[:, 0] = poses[0, 0]
    x = encode_motion(poses, root)
    assert int((x != 0).sum()) <= 151 * t
    rot, root_back, contacts = decode_motion(x)
    expected_rot = Rotation.from_rotvec(poses.reshape(-1, 3).numpy()).as_matrix().reshape(t, 24, 3, 3)
    np.testing.assert_allclose(rot.numpy(), expected_rot, atol=1e-6)
    np.testing.assert_allclose(root_back.numpy(), root.numpy())
    # frame i is in contact when the foot moves < 1 cm to frame i + 1; the last frame counts as still
    np.testing.assert_array_equal(contacts[:, 0].numpy(), [1, 1, 0, 0, 0, 1])
    rest = motion_joints(_rest_motion(1))[0, 0].numpy()
    np.testing.assert_allclose(rest, _rest_joints(), atol=1e-9)


def test_losses_against_hand_computation():
    t = 3
    d = torch.tensor([0.1, -0.2, 0.3], dtype=torch.float64)
    x0 = _rest_motion(t)
    shifted = _rest_motion(t, d.expand(t, 3))
    # every joint moves by d: |FK - FK_hat|^2 = 24 |d|^2 per frame, over 24 x 3 coordinates
    assert position_loss(shifted, x0).item() == pytest.approx(24 * 0.14 / 72)
    # constant offsets have no velocity error; a root drifting by v per frame gives |v|^2 per frame pair,
    # over the 144 rot6d + 3 root channels
    assert velocity_loss(shifted, x0).item() == pytest.approx(0.0, abs=1e-12)
    v = torch.tensor([0.0, 0.5, 0.0], dtype=torch.float64)
    drift = _rest_motion(t, torch.arange(t, dtype=torch.float64)[:, None] * v)
    assert velocity_loss(drift, x0).item() == pytest.approx(0.25 / 147)
    # contacts: predicted contact on frame 0 only (> 0.95), feet move by v -> (4 |v|^2 + 0) / (T - 1),
    # over 4 feet x 3 coordinates
    drift[0, 0, [7, 8, 10, 11], 9] = 1.0
    assert contact_loss(drift).item() == pytest.approx(4 * 0.25 / 2 / 12)
    drift[0, 0, [7, 8, 10, 11], 9] = 0.9  # below the 0.95 threshold
    assert contact_loss(drift).item() == pytest.approx(0.0)
    # reconstruction: mean over the 151 data channels per frame; unused slots ignored
    noisy = x0.clone()
    noisy[..., 0, 6] += 2.0  # one data channel off by 2 in every frame
    noisy[..., 3, 9] += 5.0  # an unused slot (joint 3 has no contact channel)
    assert reconstruction_loss(noisy, x0, "l2").item() == pytest.approx(4.0 / 151)
    assert reconstruction_loss(noisy, x0, "l1").item() == pytest.approx(2.0 / 151)
    terms = emm_losses(shifted, x0)
    assert terms["kin"].item() == pytest.approx(24 * 0.14 / 72)  # pos only (weights 1 / 0.1 / 1)


def test_emm_losses_share_one_forward_kinematics_of_the_prediction():
    """emm_losses runs FK on x0_hat once for L_pos and L_contact: its terms and their gradients are those of
    the separate loss functions, each running its own FK."""
    g = torch.Generator().manual_seed(3)
    x0 = _rest_motion(6) + 0.1 * torch.randn(1, 6, 24, 10, generator=g, dtype=torch.float64)
    x0_hat = (x0 + 0.2 * torch.randn(x0.shape, generator=g, dtype=torch.float64)).requires_grad_()
    with torch.no_grad():
        x0_hat[..., [7, 8, 10, 11], 9] = 1.0  # contacts predicted: L_contact is not zero
    terms = emm_losses(x0_hat, x0)
    (shared,) = torch.autograd.grad(terms["pos"] + terms["contact"], x0_hat)
    separate = position_loss(x0_hat, x0), contact_loss(x0_hat)
    (expected,) = torch.autograd.grad(separate[0] + separate[1], x0_hat)
    assert separate[1].item() > 0
    torch.testing.assert_close(terms["pos"], separate[0], rtol=1e-12, atol=0)
    torch.testing.assert_close(terms["contact"], separate[1], rtol=1e-12, atol=0)
    torch.testing.assert_close(shared, expected, rtol=1e-10, atol=1e-14)


def test_head_targets_invert_the_builder_camera():
    rng = np.random.default_rng(1)
    heads = rng.normal(size=(5, 3))
    rots = Rotation.random(5, random_state=2).as_matrix()
    cam = head_camera(heads, rots, np.eye(3), 64, 48, forward_offset=0.1, up_offset=0.06)
    np.testing.assert_allclose(
        head_targets_from_camera(cam.positions, cam.rotations, 0.1, 0.06), heads, atol=1e-12
    )


def test_head_guidance_moves_head_toward_target():
    torch.manual_seed(0)
    x0 = _rest_motion(8).float() + 0.05 * torch.randn(1, 8, 24, 10)
    target = motion_joints(x0)[..., 15, :] + torch.tensor([0.3, 0.0, -0.2])
    guide = HeadGuidance(target, weight=0.05, steps=5, num_steps=10)
    before = head_guidance_objective(x0, target)
    after = head_guidance_objective(guide.adjust_x0(x0, x0, torch.tensor([3])), target)
    assert after.item() < 0.5 * before.item()
    late = HeadGuidance(target, weight=0.05, start_fraction=0.2, num_steps=10)
    torch.testing.assert_close(late.adjust_x0(x0, x0, torch.tensor([5])), x0)  # t >= 0.2 T: unchanged


def _tiny_emm(use_vision: bool = True, frame_condition: bool = False) -> EMM:
    backbone = SkeletonMambaConfig(
        dim=16, depth=1, mlp_dim=32, heads=2, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16)
    )
    resnet = dict(embedding_size=8, hidden_sizes=[8, 16], depths=[1, 1], layer_type="basic")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        network = EMMConfig(
            context_dim=16,
            use_vision=use_vision,
            resnet_layers=resnet,
            freeze_resnet=False,
            heads=2,
            transformer_ff=32,
            frame_condition=frame_condition,
        )
        return EMM(backbone, network, image_size=32)


def test_one_training_step_and_sampling():
    torch.manual_seed(0)
    model = _tiny_emm()
    diffusion = GaussianDiffusion(100)
    b, t = 2, 12
    music = torch.randn(b, t, 35)
    frames = torch.rand(b, t, 3, 40, 40)
    poses = 0.3 * torch.randn(b, t, 24, 3)
    x0 = encode_motion(poses, torch.randn(b, t, 3) * 0.1)
    opt = torch.optim.AdamW(model.parameters(), lr=2e-4)
    context = model.encode_condition(music, frames)
    assert context.shape == (b, t, 16)
    context = model.drop_condition(context, torch.tensor([True, False]))
    torch.testing.assert_close(context[0], model.null_context[0].expand(t, -1))
    x_t, ts, target = diffusion.training_pair(x0)
    losses = emm_losses(model(x_t, ts, context), target)
    assert torch.isfinite(losses["loss"])
    before = [p.detach().clone() for p in model.parameters()]
    opt.zero_grad()
    losses["loss"].backward()
    assert model.vision_encoder.mlp[0].weight.grad.abs().sum() > 0  # gradient reaches the vision branch
    opt.step()
    changed = sum(not torch.equal(p0, p) for p0, p in zip(before, model.parameters(), strict=True))
    assert changed > 0.5 * len(before)
    model.eval()
    with torch.no_grad():
        cond = model.encode_condition(music, frames)
    out = ddim_sample(
        diffusion,
        model,
        (b, t, 24, 10),
        cond=cond,
        sampling_steps=3,
        guidance_weight=2.0,
        generator=torch.Generator().manual_seed(0),
    )
    assert out.shape == (b, t, 24, 10) and torch.isfinite(out).all()


def test_vision_model_needs_frames_music_only_does_not():
    model = _tiny_emm(use_vision=True)
    with pytest.raises(ValueError, match="frames"):
        model.encode_condition(torch.randn(1, 4, 35))
    assert _tiny_emm(use_vision=False).encode_condition(torch.randn(1, 4, 35)).shape == (1, 4, 16)


def test_long_form_dance_and_decoding():
    from skeleton_mamba.tasks.egodance.sampling import sample_long_dance, tokens_to_motion

    torch.manual_seed(0)
    model = _tiny_emm(use_vision=False).eval()
    music = torch.randn(40, 35)
    head = torch.zeros(40, 3)
    tokens = sample_long_dance(
        model,
        GaussianDiffusion(10),
        music,
        None,
        head,
        window=16,
        overlap=8,
        sampling_steps=2,
        generator=torch.Generator().manual_seed(0),
    )
    assert tokens.shape == (40, 24, 10) and torch.isfinite(tokens).all()
    motion = tokens_to_motion(tokens)
    assert motion.poses.shape == (40, 24, 3) and motion.joints.shape == (40, 24, 3)
    again = encode_motion(torch.from_numpy(motion.poses).double(), torch.from_numpy(motion.trans))
    np.testing.assert_allclose(motion_joints(again).numpy(), motion.joints, atol=1e-4)


def test_alignment_loss_by_hand():
    import math

    from skeleton_mamba.tasks.egodance.losses import alignment_loss

    z_a = torch.tensor([[[1.0, 0.0], [0.0, 3.0]]])  # (B=1, T=2, Dc=2); norms do not matter
    z_v = torch.tensor([[[2.0, 0.0], [1.0, 1.0]]])
    tau = 0.5
    r = 1 / math.sqrt(2)
    # cosine similarities / tau: s[i][j] = <music token i, vision token j> / tau
    s = [[1 / tau, r / tau], [0.0, r / tau]]

    def ce(logits, target):
        return -(logits[target] - math.log(sum(math.exp(v) for v in logits)))

    rows = (ce(s[0], 0) + ce(s[1], 1)) / 2  # music -> vision
    cols = (ce([s[0][0], s[1][0]], 0) + ce([s[0][1], s[1][1]], 1)) / 2  # vision -> music
    expected = 0.5 * (rows + cols)
    assert alignment_loss(z_a, z_v, tau).item() == pytest.approx(expected, rel=1e-6)
    # tokens of all windows and frames compete: (B=2, T=1) holding the same tokens gives the same loss
    assert alignment_loss(z_a.transpose(0, 1), z_v.transpose(0, 1), tau).item() == pytest.approx(expected)
    # perfectly aligned, well separated embeddings give a loss near 0
    eye = torch.eye(4)[None]
    assert alignment_loss(eye, eye, 0.01).item() < 1e-6
    with pytest.raises(ValueError, match="differ in shape"):
        alignment_loss(z_a, z_v[:, :1])


def test_batched_classifier_free_guidance_equals_two_calls():
    from skeleton_mamba.tasks.training.diffusion import guided_x0

    torch.manual_seed(0)
    model = _tiny_emm(use_vision=False).eval()
    x_t, t = torch.randn(2, 8, 24, 10), torch.tensor([5, 17])
    with torch.no_grad():
        context = model.encode_condition(torch.randn(2, 8, 35))
        cond, unc = model(x_t, t, context), model(x_t, t, None)
        batched = guided_x0(model, x_t, t, context, 2.0)  # EMM.null_condition: one call on 2B samples
    torch.testing.assert_close(batched, unc + 2.0 * (cond - unc), rtol=1e-4, atol=1e-5)


def test_music_features_are_standardised_with_training_statistics():
    from skeleton_mamba.tasks.egodance.encoders import MusicEncoder

    torch.manual_seed(0)
    encoder = MusicEncoder(music_dim=3, dim=8, layers=1, heads=2, ff_dim=16, dropout=0.0).eval()
    # channels on the scales of librosa's: MFCC 0 (-300 +- 165), a one-hot beat, a constant channel
    mfcc0, beat = -300 + 165 * torch.randn(2, 50), (torch.rand(2, 50) < 0.1).float()
    music = torch.stack([mfcc0, beat, torch.ones(2, 50)], -1)
    raw_state = {k: v.clone() for k, v in encoder.state_dict().items()}
    encoder.set_statistics(music)
    flat = music.reshape(-1, 3).double()
    mean, std = flat.mean(0), flat.std(0, unbiased=False).clamp(min=1e-3)  # the constant channel: floor
    torch.testing.assert_close(encoder.feature_mean, mean.float())
    torch.testing.assert_close(encoder.feature_std, std.float())
    seen = {}
    encoder.proj.register_forward_pre_hook(lambda module, args: seen.setdefault("x", args[0]))
    with torch.no_grad():
        encoder(music)
    torch.testing.assert_close(seen["x"], ((music.double() - mean) / std).float(), rtol=1e-5, atol=1e-5)
    assert seen["x"][..., :2].reshape(-1, 2).std(0).sub(1).abs().max() < 0.02  # unit scale, not hundreds
    # the statistics are part of the weights: a state dict without them is refused, not filled in
    old = {k: v for k, v in raw_state.items() if not k.startswith("feature_")}
    with pytest.raises(RuntimeError, match="feature_mean"):
        encoder.load_state_dict(old)
    with pytest.raises(ValueError, match="NaN"):
        encoder.set_statistics(torch.full((1, 4, 3), float("nan")))


def test_frame_condition_adds_condition_t_to_the_pose_embedding_of_frame_t():
    torch.manual_seed(0)
    model = _tiny_emm(use_vision=False, frame_condition=True).eval()
    assert _tiny_emm(use_vision=False).frame_condition is None  # off by default ([EgoMusic]'s network)
    x_t, t = torch.randn(1, 8, 24, 10), torch.tensor([7])
    context = torch.randn(1, 8, 16)
    inputs = []
    model.backbone.register_forward_pre_hook(lambda module, args: inputs.append(args[0].clone()))
    changed = context.clone()
    changed[0, 3] += 1.0
    with torch.no_grad():
        model(x_t, t, context)
        model(x_t, t, changed)
    delta = inputs[1] - inputs[0]  # (1, T, J, D): the pose embeddings fed to the backbone
    expected = model.frame_condition.weight @ torch.ones(16)  # W (c_3 + 1) - W c_3
    assert delta[0, [0, 1, 2, 4, 5, 6, 7]].abs().max() == 0  # no other frame moves
    # every joint of frame 3 moves by W 1
    torch.testing.assert_close(delta[0, 3], expected.expand(24, -1), rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="one condition token per frame"):
        model(x_t, t, context[:, :5])
    # a network's weights hold its frame_condition or not: the two do not load into each other
    plain = _tiny_emm(use_vision=False).eval()
    with pytest.raises(RuntimeError, match="frame_condition"):
        model.load_state_dict(plain.state_dict())
