"""Dance metrics (kinetic / geometric features, FID, Div, BeatAlign, PFC, MMV) against independent values."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import linalg
from scipy.ndimage import gaussian_filter

from skeleton_mamba.tasks.motion.metrics import (
    MMV,
    PFC,
    BeatAlign,
    FrechetMotionDistance,
    MotionDiversity,
    alignment_score,
    average_pairwise_distance,
    frechet_distance,
    geometric_features,
    kinetic_features,
    visual_beats,
)
from skeleton_mamba.tasks.motion.metrics.geometric import GEOMETRIC_FEATURE_NAMES, HUMERUS_LENGTH
from skeleton_mamba.tasks.motion.metrics.mmv import flow_magnitudes, load_video_frames
from tests.helpers.motions import published_kinetic, rest_pose

# ----------------------------------------------------------------------------------------- kinetic


def test_kinetic_static_joint_hand_values():
    # A joint at rest at c: no kinetic energy; the published EE is |59 c / dt| / ... = 59 * 60 * |c|.
    c = np.array([0.3, 1.2, -0.4])
    positions = torch.tensor(np.tile(c, (5, 1, 1)))
    buggy = kinetic_features(positions).numpy()
    fixed = kinetic_features(positions, published_acceleration_bug=False).numpy()
    np.testing.assert_allclose(buggy[:2], 0.0, atol=1e-12)
    np.testing.assert_allclose(buggy[2], 59 * 60 * np.linalg.norm(c), rtol=1e-12)
    np.testing.assert_allclose(fixed, 0.0, atol=1e-9)


def test_kinetic_constant_velocity_hand_values():
    u = np.array([0.01, 0.02, -0.03])  # metres per frame
    positions = torch.tensor(np.arange(6)[:, None, None] * u)  # (6, 1, 3), starts at the origin
    feats = kinetic_features(positions, published_acceleration_bug=False).numpy()
    np.testing.assert_allclose(feats[0], (u[0] ** 2 + u[2] ** 2) * 60**2, rtol=1e-12)  # KE_h
    np.testing.assert_allclose(feats[1], u[1] ** 2 * 60**2, rtol=1e-12)  # KE_v
    np.testing.assert_allclose(feats[2], 0.0, atol=1e-9)  # no acceleration
    # z-up: the vertical component is z
    feats_z = kinetic_features(positions, up_axis=2, published_acceleration_bug=False).numpy()
    np.testing.assert_allclose(feats_z[1], u[2] ** 2 * 60**2, rtol=1e-12)


def test_kinetic_four_frames_hand_values():
    # T = 4: every window covers all samples, so v = (p3 - p0) / (3 dt) and EE = |(a1 + a2) / 2|.
    p = np.array([[0.0, 0, 0], [0.1, 0.0, 0], [0.1, 0.2, 0], [0.4, 0.2, 0.1]])
    dt = 1 / 60
    v = (p[3] - p[0]) / (3 * dt)
    a1 = ((p[2] - p[1]) / dt - (p[1] - p[0]) / dt) / dt
    a2 = ((p[3] - p[2]) / dt - (p[2] - p[1]) / dt) / dt
    expected = [v[0] ** 2 + v[2] ** 2, v[1] ** 2, np.linalg.norm((a1 + a2) / 2)]
    got = kinetic_features(torch.tensor(p[:, None]), published_acceleration_bug=False).numpy()
    np.testing.assert_allclose(got, expected, rtol=1e-12)


@pytest.mark.parametrize("bug", [True, False])
def test_kinetic_matches_published_loop(bug):
    positions = np.random.default_rng(0).normal(size=(9, 3, 3))
    got = kinetic_features(torch.tensor(positions), published_acceleration_bug=bug).numpy()
    np.testing.assert_allclose(got, published_kinetic(positions, bug), rtol=1e-10)


def test_kinetic_rejects_short_sequences():
    with pytest.raises(ValueError, match="at least 3 frames"):
        kinetic_features(torch.zeros(2, 24, 3))


# --------------------------------------------------------------------------------------- geometric


def test_geometric_hand_cases():
    rest = rest_pose()
    upright_1 = rest + [0.01, 0, 0]  # root moves 0.01 m/frame -> 1.2 m/s > 2.3 hl = 0.59 m/s
    upright_2 = upright_1 + [0.004, 0, 0]  # 0.48 m/s: not fast
    lying = upright_2.copy()
    rel = upright_2 - upright_2[0]
    lying = upright_2[0] + rel @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]).T  # 90 deg about z
    feats = geometric_features(torch.tensor(np.stack([rest, upright_1, upright_2, lying]))).numpy()
    assert feats.shape == (32,) and len(GEOMETRIC_FEATURE_NAMES) == 32
    assert GEOMETRIC_FEATURE_NAMES[31] == "fast(root)"
    np.testing.assert_allclose(feats[31], 1 / 3)  # root fast only on frame 1
    assert GEOMETRIC_FEATURE_NAMES[28] == "angle(neck, root, zero, y_unit)"
    np.testing.assert_allclose(feats[28], 1 / 3)  # torso 70-110 deg from vertical only when lying
    # nplane(zero, y_unit, y_min, ankle; 1.2 hl): ankle height over the lowest joint of the frame. Standing,
    # the ankles are low; lying on the side, the lowest joint is a hand and the ankles are far above it.
    frames = [upright_1, upright_2, lying]
    for index, ankle in ((16, 8), (17, 7)):
        heights = [f[ankle, 1] - f[:, 1].min() for f in frames]
        assert heights[0] < 1.2 * HUMERUS_LENGTH
        np.testing.assert_allclose(feats[index], np.mean([h > 1.2 * HUMERUS_LENGTH for h in heights]))


def test_geometric_lifted_ankle_and_rigid_translation():
    rest = rest_pose()
    lifted = rest.copy()
    lifted[8, 1] += 0.5  # right ankle 0.5 m up: well above 1.2 hl = 0.31 m over the lowest joint
    seq = np.stack([rest, lifted, lifted + [0, 0, 0.001]])
    feats = geometric_features(torch.tensor(seq)).numpy()
    np.testing.assert_allclose(feats[16], 1.0)  # rankle high on both frames
    np.testing.assert_allclose(feats[17], 0.0)  # lankle stays low
    # A rigid translation has no relative velocity: move / nmove predicates (positive thresholds) are off.
    shifted = np.stack([rest + [0.05 * t, 0, 0] for t in range(4)])
    feats = geometric_features(torch.tensor(shifted)).numpy()
    np.testing.assert_allclose(feats[[0, 1, 4, 5, 9, 10, 11]], 0.0)


# -------------------------------------------------------------------------------------- FID and Div


def scipy_fid(x: np.ndarray, y: np.ndarray) -> float:
    mu1, mu2 = x.mean(0), y.mean(0)
    s1, s2 = np.cov(x, rowvar=False), np.cov(y, rowvar=False)
    covmean = linalg.sqrtm(s1 @ s2).real
    return float(((mu1 - mu2) ** 2).sum() + np.trace(s1) + np.trace(s2) - 2 * np.trace(covmean))


@pytest.mark.parametrize("n_x, n_y, dims", [(300, 250, 12), (40, 300, 72)])  # 40 in 72-d: singular
def test_frechet_distance_matches_scipy_sqrtm(n_x, n_y, dims):
    rng = np.random.default_rng(1)
    x = rng.normal(size=(n_x, dims))
    y = rng.normal(size=(n_y, dims)) @ rng.normal(size=(dims, dims)) * 0.5 + 0.3
    got = frechet_distance(
        torch.tensor(x.mean(0)), torch.tensor(np.cov(x, rowvar=False)),
        torch.tensor(y.mean(0)), torch.tensor(np.cov(y, rowvar=False)),
    ).item()  # fmt: skip
    assert got == pytest.approx(scipy_fid(x, y), rel=1e-4)


def test_fid_metric_protocol_matches_scipy_and_grows_with_shift():
    rng = np.random.default_rng(2)
    # Random-walk dances: 30 real and 20 generated sequences of 40 frames.
    real = np.cumsum(rng.normal(scale=0.01, size=(30, 40, 24, 3)), axis=1) + rest_pose()
    fake = np.cumsum(rng.normal(scale=0.013, size=(20, 40, 24, 3)), axis=1) + rest_pose()
    metric = FrechetMotionDistance("kinetic")
    metric.update(torch.tensor(real[:15]), real=True)
    metric.update(list(torch.tensor(real[15:])), real=True)  # list input, same result
    metric.update(torch.tensor(fake), real=False)
    # Independent pipeline: features -> normalise by real stats (np.std) -> scipy FID.
    fr = kinetic_features(torch.tensor(real)).numpy()
    ff = kinetic_features(torch.tensor(fake)).numpy()
    mean, std = fr.mean(0), fr.std(0) + 1e-10
    expected = scipy_fid((ff - mean) / std, (fr - mean) / std)
    assert metric.compute().item() == pytest.approx(expected, rel=1e-4)

    # A set against itself is ~0, and the distance grows with a shift of the generated features.
    feats = torch.tensor(rng.normal(size=(200, 8)))
    values = []
    for shift in (0.0, 0.5, 1.0, 2.0):
        m = FrechetMotionDistance("kinetic")
        m.update_features(torch.cat([feats, torch.zeros(200, 64)], 1), real=True)
        m.update_features(torch.cat([feats + shift, torch.zeros(200, 64)], 1), real=False)
        values.append(m.compute().item())
    assert abs(values[0]) < 1e-6
    assert values[1] < values[2] < values[3]


def test_fid_keeps_real_features_when_asked():
    m = FrechetMotionDistance("kinetic", reset_real_features=False)
    feats = torch.randn(10, 72, dtype=torch.float64)
    m.update_features(feats, real=True)
    m.update_features(feats, real=False)
    m.reset()
    m.update_features(feats, real=False)
    assert abs(m.compute().item()) < 1e-4  # 10 samples in 72-d: rank-deficient, trace ~ 144
    with pytest.warns(UserWarning, match="before the ``update``"), pytest.raises(RuntimeError, match="real"):
        FrechetMotionDistance("kinetic").compute()


def test_constant_real_features_are_counted_and_make_fid_astronomic():
    """A geometric feature that never varies over the real set (std 0) is divided by 1e-10 in the reference
    normalisation: a generated set that sets it in one clip has FID_g of order 1e18, which the count flags."""
    rng = np.random.default_rng(3)
    real = torch.tensor(rng.uniform(0.1, 0.9, size=(8, 32)))
    real[:, [6, 7]] = 0.0  # two features no real clip ever sets
    fake = real.clone() + 0.01 * torch.tensor(rng.standard_normal((8, 32)))
    fake[:, [6, 7]] = 0.0
    m = FrechetMotionDistance("geometric")
    assert m.constant_real_features() == 0  # nothing added yet
    m.update_features(real, real=True)
    assert m.constant_real_features() == 2
    m.update_features(fake, real=False)
    assert m.compute().item() < 10  # the constant features agree: an ordinary figure
    extra = fake[:1].clone()
    extra[:, 6] = 0.02
    m.update_features(extra, real=False)
    assert m.compute().item() > 1e12  # one generated clip sets a constant feature by 0.02


def test_diversity_hand_computation():
    fake = torch.tensor([[0.0, 0.0], [3.0, 4.0], [6.0, 8.0]])
    assert average_pairwise_distance(fake).item() == pytest.approx((5 + 10 + 5) / 3)
    # Reference features with mean 0 and population std 1 leave the generated features unchanged.
    m = MotionDiversity("kinetic")
    real = torch.zeros(2, 72, dtype=torch.float64)
    real[0], real[1] = -1.0, 1.0
    gen = torch.zeros(3, 72, dtype=torch.float64)
    gen[:, :2] = fake
    m.update_features(real, real=True)
    m.update_features(gen, real=False)
    assert m.compute().item() == pytest.approx(20 / 3, rel=1e-8)


# --------------------------------------------------------------------------------------- BeatAlign


def cosine_dance(t_len: int, period: int, phase: float) -> np.ndarray:
    """(T, 24, 3) joints whose speed |p_t - p_(t-1)| is ~|sin| with minima every period/2 frames."""
    t = np.arange(t_len)[:, None, None]
    x = 0.2 * np.cos(2 * np.pi * (t - phase) / period)
    return rest_pose()[None] + np.concatenate([x, np.zeros_like(x), np.zeros_like(x)], axis=-1)


def test_alignment_score_hand_values():
    assert alignment_score([10], [13, 40], sigma=3) == pytest.approx(math.exp(-9 / 18))
    assert alignment_score([], [1, 2], sigma=3) == 0.0


def test_beat_align_aligned_beats_shuffled_and_variants_differ():
    t_len, period = 600, 60  # speed minima every 30 frames (120 BPM at 60 fps)
    aligned = cosine_dance(t_len, period, phase=0.5)
    shuffled = aligned[np.random.default_rng(3).permutation(t_len)]
    beats = np.zeros(t_len, dtype=bool)
    beats[30::30] = True
    for variant in ("fact", "bailando"):
        good, bad = BeatAlign(variant), BeatAlign(variant)
        good.update(torch.tensor(aligned[None]), [beats])
        bad.update(torch.tensor(shuffled[None]), [beats])
        assert good.compute().item() > 0.9
        assert good.compute().item() > bad.compute().item() + 0.3
    # Music beats on every other motion beat: FACT (mean over motion beats) halves, Bailando (mean over
    # music beats) stays high.
    sparse = np.zeros(t_len, dtype=bool)
    sparse[60::60] = True
    fact, bailando = BeatAlign("fact"), BeatAlign("bailando")
    fact.update(torch.tensor(aligned[None]), [sparse])
    bailando.update(torch.tensor(aligned[None]), [np.flatnonzero(sparse)])  # index form
    assert 0.4 < fact.compute().item() < 0.6
    assert bailando.compute().item() > 0.9
    # start_frame (FACT: 120, after the seed): earlier beats do not count.
    late = np.zeros(t_len, dtype=bool)
    late[150::30] = True  # no music beat before frame 150
    whole, after = BeatAlign("fact"), BeatAlign("fact", start_frame=150)
    whole.update(torch.tensor(aligned[None]), [late])
    after.update(torch.tensor(aligned[None]), [late])
    assert after.compute().item() > 0.9 > whole.compute().item() + 0.1
    with pytest.raises(ValueError, match="variant"):
        BeatAlign("other")


# --------------------------------------------------------------------------------------------- PFC


def test_pfc_hand_cases():
    s_len = 4
    joints = np.zeros((s_len, 24, 3))
    t = np.arange(s_len)
    joints[:, 7, 0] = 0.1 * t  # lankle: 0.1 m per frame horizontally
    joints[:, 10, 0] = 0.2 * t  # ltoes 0.2 -> left min 0.1
    joints[:, 8, 1] = 0.3 * t  # rankle 0.3
    joints[:, 11, 1] = 0.05 * t  # rtoes 0.05 -> right min 0.05
    up = joints.copy()
    up[:, 0, 2] = [0, 0, 1, 3]  # equal upward root accelerations -> normalised [1, 1]
    metric = PFC()
    metric.update(torch.tensor(up[None]))
    assert metric.compute().item() == pytest.approx(10000 * 0.1 * 0.05)
    clamp = joints.copy()
    clamp[:, 0] = [[0, 0, 0], [0, 0, 0], [1, 0, -1], [1, 0, -1]]
    # a = (900, 0, -900) -> z clamped -> 900; then (-900, 0, 900) -> 900 sqrt 2; normalised [1/sqrt2, 1].
    metric = PFC()
    metric.update(torch.tensor(clamp[None]))
    assert metric.compute().item() == pytest.approx(10000 * 0.005 * (1 / math.sqrt(2) + 1) / 2)
    both = PFC()
    both.update([torch.tensor(up), torch.tensor(clamp)])
    assert both.compute().item() == pytest.approx(10000 * 0.005 * (1 + (1 / math.sqrt(2) + 1) / 2) / 2)


# --------------------------------------------------------------------------------------------- MMV


def moving_texture(shifts: list[int]) -> np.ndarray:
    """(len(shifts) + 1, 64, 64, 3) uint8 frames of a smooth texture rolled right by shifts[t] px."""
    rng = np.random.default_rng(4)
    texture = gaussian_filter(rng.normal(size=(64, 64)), 2.0)
    texture = (255 * (texture - texture.min()) / np.ptp(texture)).astype(np.uint8)
    frames, offset = [texture], 0
    for s in shifts:
        offset += s
        frames.append(np.roll(texture, offset, axis=1))
    return np.repeat(np.stack(frames)[..., None], 3, axis=-1)


def test_mmv_on_synthetic_video(tmp_path):
    import imageio.v2 as imageio

    shifts = [abs(t % 10 - 5) for t in range(66)]  # 5 4 3 2 1 0 1 2 ... minima at t = 5, 15, ...
    frames = moving_texture(shifts)
    mags = flow_magnitudes(frames)
    assert np.corrcoef(mags, shifts)[0, 1] > 0.95
    expected = np.arange(5, 60, 10)  # (65 is the last sample: an end point is never a local minimum)
    np.testing.assert_array_equal(visual_beats(frames, fps=30), expected)
    # The same frames as an image folder.
    folder = tmp_path / "frames"
    folder.mkdir()
    for i, f in enumerate(frames):
        imageio.imwrite(folder / f"{i:04d}.png", f)
    np.testing.assert_array_equal(load_video_frames(folder), frames)

    # Whole body and head speed minima every 10 frames, on the video minima and the music beats.
    body = cosine_dance(67, 20, phase=-5.0 + 0.5)  # envelope minima at t = 5, 15, ... (see BeatAlign test)
    music = np.zeros(67, dtype=bool)
    music[expected] = True
    metric = MMV(fps=30)
    metric.update(torch.tensor(body[None]), [music], videos=[frames])
    good = metric.compute()
    assert good["mm"].item() > 0.9 and good["mv"].item() > 0.9
    assert good["mmv"].item() == pytest.approx(0.5 * good["mm"].item() + 0.5 * good["mv"].item())
    off = MMV(fps=30)
    off.update(torch.tensor(body[None]), [music], video_beats=[expected + 5])  # half a period off
    assert off.compute()["mv"].item() < 0.2
    with pytest.raises(ValueError, match="exactly one"):
        off.update(torch.tensor(body[None]), [music])


def test_video_file_input_and_reader_errors(tmp_path):
    import imageio.v2 as imageio

    frames = moving_texture([2] * 11)  # 12 frames of 64 x 64
    video = tmp_path / "ego.mp4"
    imageio.mimwrite(video, frames, fps=30)
    decoded = load_video_frames(video)
    assert decoded.shape == frames.shape and decoded.dtype == np.uint8
    assert np.abs(decoded.astype(float) - frames).mean() < 10  # lossy codec, same pictures
    with pytest.raises(FileNotFoundError):
        load_video_frames(tmp_path / "missing.mp4")
    with pytest.raises(ValueError, match="no image files"):
        load_video_frames(tmp_path)
    with pytest.raises(ValueError, match="uint8"):
        load_video_frames(np.zeros((3, 8, 8, 3), dtype=np.float32))
