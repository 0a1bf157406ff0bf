"""HumanML3D: the 263-d layout, statistics, recover_from_ric, file reading, convert and render."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from PIL import Image
from scipy.spatial.transform import Rotation

from skeleton_mamba.errors import DatasetNotFoundError, InputError
from skeleton_mamba.skeletons import HUMANML3D22
from skeleton_mamba.tasks.motion.formats import humanml3d_features as F
from skeleton_mamba.tasks.motion.formats.humanml3d_features import read_statistics
from skeleton_mamba.tasks.motion.render.skeleton import RenderStyle, render_motion
from skeleton_mamba.tasks.text2motion.convert_cli import main as convert_main
from skeleton_mamba.tasks.text2motion.humanml3d import (
    crop_length,
    is_mirrored,
    load_clips,
    mirror_source,
    read_captions,
    read_motion,
    read_split,
)

SAMPLE = "humanml3d/new_joint_vecs/012314.npy"


@pytest.fixture(scope="module")
def sample(shared_data):
    return np.load(shared_data / SAMPLE).astype(np.float64)


def test_layout_slices_match_the_published_table():
    # motion_representation.ipynb: 1 + 2 + 1 + 21*3 + 21*6 + 22*3 + 4 = 263; KIT-ML (21 joints) 251.
    assert F.FEATURE_DIM == 263 and F.feature_dim(21) == 251
    root = (F.ROOT_ROT_VELOCITY, F.ROOT_LINEAR_VELOCITY, F.ROOT_HEIGHT)
    assert root == (slice(0, 1), slice(1, 3), slice(3, 4))
    assert (F.RIC, F.ROT6D, F.LOCAL_VELOCITY, F.FOOT_CONTACT) == (
        slice(4, 67),
        slice(67, 193),
        slice(193, 259),
        slice(259, 263),
    )


def test_std_is_constant_inside_each_slice_of_the_real_statistics(shared_data):
    # cal_mean_variance.ipynb replaces each group's Std by the group mean: the file itself marks the groups.
    _, std = read_statistics(shared_data / "humanml3d")
    groups = [F.ROOT_ROT_VELOCITY, F.ROOT_LINEAR_VELOCITY, F.ROOT_HEIGHT, F.RIC, F.ROT6D, F.LOCAL_VELOCITY]
    groups.append(F.FOOT_CONTACT)
    for group in groups:
        assert np.ptp(std[group]) < 1e-6 * std[group][0], group
    assert len({round(float(std[g][0]), 6) for g in groups}) == len(groups)


def test_normalisation_round_trip_on_the_sample(shared_data, sample):
    mean, std = (torch.from_numpy(a).double() for a in read_statistics(shared_data / "humanml3d"))
    x = torch.from_numpy(sample)
    z = F.normalize(x, mean, std)
    assert torch.allclose(z[5, 10], (x[5, 10] - mean[10]) / std[10])
    assert torch.allclose(F.denormalize(z, mean, std), x, atol=1e-12)


def test_recovered_joints_have_constant_plausible_bones(sample):
    joints = F.recover_from_ric(torch.from_numpy(sample))
    assert joints.shape == (170, 22, 3)
    parents = torch.tensor(HUMANML3D22.parents[1:])
    bones = (joints[:, 1:] - joints[:, parents]).norm(dim=-1)  # (T, 21)
    assert bones.std(0).max() < 1e-5  # retargeted to one skeleton: lengths never change
    names = HUMANML3D22.joint_names
    length = dict(zip(names[1:], bones.mean(0).tolist(), strict=True))
    assert 0.3 < length["left_knee"] < 0.5 and 0.3 < length["right_ankle"] < 0.5  # thigh, shin
    assert abs(length["left_knee"] - length["right_knee"]) < 0.01  # near-symmetric target skeleton
    assert 0.2 < length["left_wrist"] < 0.3  # forearm
    height = joints[0, 15, 1] - joints[0, :, 1].min()
    assert 1.2 < height < 1.9  # head joint (ear level) above the lowest joint, metres
    assert joints[:, :, 1].min() > -0.05  # put on the floor
    assert torch.allclose(joints[0, 0, [0, 2]], torch.zeros(2, dtype=torch.float64))  # first root XZ at 0


def test_recovered_joints_reproduce_the_stored_velocities_and_contacts(sample):
    # Independent of the recovery code: scipy rotations and the notebook's definitions of the
    # local velocity (qrot(r_rot[t], p[t+1] - p[t])) and of foot contact (|dp|^2 < 0.002).
    joints = F.recover_from_ric(torch.from_numpy(sample)).numpy()
    angle = np.concatenate([[0.0], np.cumsum(sample[:-1, 0])])
    yaw = Rotation.from_quat(np.stack([0 * angle, np.sin(angle), 0 * angle, np.cos(angle)], axis=1))
    diffs = joints[1:] - joints[:-1]  # (T-1, 22, 3)
    for t in range(0, len(diffs), 7):
        local = yaw[t].apply(diffs[t])
        np.testing.assert_allclose(local, sample[t, 193:259].reshape(22, 3), atol=1e-5)
    feet = (diffs[:, [7, 10, 8, 11]] ** 2).sum(-1) < 0.002
    assert (feet == (sample[:-1, 259:263] > 0.5)).mean() == 1.0


def test_recover_from_ric_on_hand_made_features():
    # Two frames; root turns by 0.3 rad (quaternion half-angle) and moves 0.1 forward in its frame.
    f = torch.zeros(3, 263, dtype=torch.float64)
    f[:, 0] = 0.3
    f[:, 2] = 0.1  # forward (+Z) velocity in the facing frame
    f[:, 3] = 0.9
    f[:, 4:7] = torch.tensor([0.2, 0.8, 0.0])  # joint 1 relative to the root XZ
    joints = F.recover_from_ric(f)
    # frame 2: angle 0.6 -> rotation about Y by -1.2 rad applied to the stored vectors.
    r1 = Rotation.from_rotvec([0, -0.6, 0])
    r2 = Rotation.from_rotvec([0, -1.2, 0])
    root2 = r1.apply([0, 0, 0.1]) + r2.apply([0, 0, 0.1])
    np.testing.assert_allclose(joints[2, 0].numpy(), [root2[0], 0.9, root2[2]], atol=1e-12)
    expected = r2.apply([0.2, 0.8, 0.0]) + [root2[0], 0, root2[2]]
    np.testing.assert_allclose(joints[2, 1].numpy(), expected, atol=1e-12)
    with pytest.raises(ValueError, match="263"):
        F.recover_from_ric(torch.zeros(3, 262))


def test_real_split_lists_and_mirrored_ids(shared_data):
    root = shared_data / "humanml3d"
    train, val, test = (read_split(root, s) for s in ("train", "val", "test"))
    assert (len(train), len(val), len(test)) == (23384, 1460, 4384)
    assert sum(map(is_mirrored, train)) == 11692 and sum(map(is_mirrored, test)) == 2192
    assert mirror_source("M012314") == "012314" and mirror_source("012314") == "012314"
    assert read_motion(root, "012314").shape == (170, 263)


def _write_dataset(root, motions, texts, split):
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    for name, frames in motions.items():
        array = np.zeros((frames, 263), np.float32)
        array[:, 0] = np.arange(frames)
        np.save(root / "new_joint_vecs" / f"{name}.npy", array)
    for name, lines in texts.items():
        (root / "texts" / f"{name}.txt").write_text("\n".join(lines) + "\n")
    (root / "train.txt").write_text("\n".join(split) + "\n")


def test_clips_follow_the_length_rules_and_sub_clips(tmp_path):
    _write_dataset(
        tmp_path,
        {"000001": 120, "M000001": 120, "000002": 30, "000003": 200},
        {
            "000001": [
                "a person walks.#a/DET person/NOUN walk/VERB#0.0#0.0",
                "then jumps.#jump/VERB#2.0#4.5",  # frames 40..90: kept
                "a wave.#wave/NOUN#0.5#2.0",  # frames 10..40: 30 < 40 dropped
            ],
            "M000001": ["mirrored.#mirror/VERB#nan#nan"],
            "000002": ["too short#short/ADJ#0.0#0.0"],
            "000003": ["too long#long/ADJ#0.0#0.0"],
        },
        ["000001", "M000001", "000002", "000003"],
    )
    clips = load_clips(tmp_path, "train")
    summary = [(c.motion_id, c.start_frame, c.length, [k.text for k in c.captions]) for c in clips]
    assert summary == [
        ("000001", 40, 50, ["then jumps."]),
        ("000001", 0, 120, ["a person walks."]),
        ("M000001", 0, 120, ["mirrored."]),
    ]
    assert clips[0].features[0, 0] == 40  # cut at floor(2.0 * 20)
    assert read_captions(tmp_path, "000001")[0].tokens == ("a/DET", "person/NOUN", "walk/VERB")


def test_bad_files_raise_errors_naming_the_file(tmp_path):
    _write_dataset(tmp_path, {"000001": 50}, {"000001": ["no fields"]}, ["000001", "000009"])
    with pytest.raises(ValueError, match=r"texts/000001.txt:1: want"):
        read_captions(tmp_path, "000001")
    with pytest.raises(DatasetNotFoundError, match=r"000009.npy: missing HumanML3D motion"):
        read_motion(tmp_path, "000009")
    np.save(tmp_path / "new_joint_vecs" / "000004.npy", np.zeros((10, 251), np.float32))
    with pytest.raises(ValueError, match=r"000004.npy: expected HumanML3D features \(T >= 1, 263\)"):
        read_motion(tmp_path, "000004")
    (tmp_path / "val.txt").write_text("000001\nabc\n")
    with pytest.raises(ValueError, match=r"val.txt:2: malformed"):
        read_split(tmp_path, "val")
    with pytest.raises(DatasetNotFoundError, match="Mean"):
        read_statistics(tmp_path)


def test_crop_lengths_are_multiples_of_four_at_most_196():
    rng = np.random.default_rng(0)
    lengths = {crop_length(199, rng) for _ in range(60)}
    assert lengths == {196, 192}  # "single" (2/3) or "double" (1/3) coin
    assert all(crop_length(n, rng) % 4 == 0 and crop_length(n, rng) >= n - 7 for n in range(40, 200))


def test_convert_cli_and_render_the_sample(shared_data, sample, tmp_path):
    out = tmp_path / "joints.npy"
    assert convert_main([str(shared_data / SAMPLE), "--out", str(out)]) == 0
    joints = np.load(out)
    assert joints.shape == (170, 22, 3) and joints.dtype == np.float32
    np.testing.assert_allclose(joints, F.recover_from_ric(torch.from_numpy(sample)).numpy(), atol=1e-5)
    # normalised input de-normalised with the shipped statistics gives the same joints
    mean, std = read_statistics(shared_data / "humanml3d")
    np.save(tmp_path / "norm.npy", ((sample - mean) / std).astype(np.float32))
    args = [str(tmp_path / "norm.npy"), "--out", str(tmp_path / "j2.npy"), "--normalized"]
    assert convert_main([*args, "--stats", str(shared_data / "humanml3d")]) == 0
    np.testing.assert_allclose(np.load(tmp_path / "j2.npy"), joints, atol=1e-4)
    with pytest.raises(InputError, match=r"^--normalized needs --stats DIR \(Mean.npy, Std.npy\)$"):
        convert_main(args)  # sm prints it as one line, exit 2
    gif = render_motion(
        joints[:30],
        HUMANML3D22.parents,
        tmp_path / "clip.gif",
        fps=20,
        names=HUMANML3D22.joint_names,
        style=RenderStyle(width=160, height=120),
        progress=False,
    )
    with Image.open(gif) as image:
        assert image.n_frames == 30 and image.size == (160, 120)


def test_joints_to_features_reproduces_the_real_sample_after_frame_0(sample):
    # The sample's own features (not our code) are the oracle; frame 0 of the dataset is special (its
    # root rotation velocity and ric carry the heading offset of the original processing).
    joints = F.recover_from_ric(torch.from_numpy(sample))
    features = F.joints_to_features(joints).numpy()  # (169, 263) from 170 positions
    real = sample[1:-1]
    tolerances = [(F.ROOT_ROT_VELOCITY, 1e-3), (F.ROOT_LINEAR_VELOCITY, 1e-3), (F.ROOT_HEIGHT, 1e-9)]
    tolerances += [(F.RIC, 1e-2), (F.LOCAL_VELOCITY, 1e-3), (F.FOOT_CONTACT, 0.0)]
    for part, tolerance in tolerances:
        np.testing.assert_allclose(features[1:, part], real[:, part], atol=tolerance, err_msg=str(part))


def test_joints_to_features_round_trips_through_recover_from_ric():
    from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance

    motion = synthesize_dance(120, 3.0, fps=20, style="sway", seed=1)
    joints = torch.from_numpy(motion.joint_positions()[:, :22]).double()
    turn = torch.from_numpy(Rotation.from_rotvec([0, 1.0, 0]).as_matrix())
    joints = joints @ turn.T + torch.tensor([2.0, 0.5, 1.0])  # anywhere, facing anywhere
    features = F.joints_to_features(joints)
    assert features.shape == (59, 263)
    canonical = F.canonicalize(joints)
    torch.testing.assert_close(F.recover_from_ric(features), canonical[:-1], atol=1e-9, rtol=0)
    assert canonical[..., 1].min() == 0 and canonical[0, 0, [0, 2]].abs().max() < 1e-12
    assert abs(F.facing_angle(canonical)[0]) < 1e-9
