"""The HumanML3D 263-d motion representation: its slices, normalisation, joint recovery and feature files.

Layout for J = 22 joints (``EricGuo5513/HumanML3D motion_representation.ipynb``):

=============  =====  ==========================================================================
slice          dims   content
=============  =====  ==========================================================================
``[0:1]``      1      root angular velocity about Y (per frame)
``[1:3]``      2      root linear velocity on XZ, in the root facing frame
``[3:4]``      1      root height Y
``[4:67]``     63     ric: joints 1..21 relative to the root's XZ, rotated to face +Z
``[67:193]``   126    6D local rotations of joints 1..21
``[193:259]``  66     velocities of all 22 joints, rotated by the root facing
``[259:263]``  4      foot contacts: left (7, 10) then right (8, 11)
=============  =====  ==========================================================================

:func:`recover_from_ric` is the dataset's procedure (same in ``text-to-motion`` and MDM
``motion_process.py``) written with the toolkit's kornia quaternion maths; quaternions are (w, x, y, z).
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.errors import DataFileError, DatasetNotFoundError
from skeleton_mamba.tasks.motion.body.rotations import quaternion_to_matrix
from skeleton_mamba.tasks.motion.io.value_checks import check_finite, check_magnitude, check_real, load_npy

__all__ = [
    "NUM_JOINTS",
    "FEATURE_DIM",
    "ROOT_ROT_VELOCITY",
    "ROOT_LINEAR_VELOCITY",
    "ROOT_HEIGHT",
    "RIC",
    "ROT6D",
    "LOCAL_VELOCITY",
    "FOOT_CONTACT",
    "FPS",
    "feature_dim",
    "normalize",
    "denormalize",
    "recover_root_rotation_position",
    "recover_from_ric",
    "facing_angle",
    "canonicalize",
    "joints_to_features",
    "group_statistics",
    "FEATURE_MAGNITUDE_LIMIT",
    "NonFiniteFeaturesError",
    "check_features",
    "read_feature_vector",
    "read_features",
    "read_statistics",
]

NUM_JOINTS = 22
FPS = 20.0


def feature_dim(num_joints: int = NUM_JOINTS) -> int:
    """Feature size ``8 + (J - 1) * 9 + 3 J`` (263 for HumanML3D's 22 joints, 251 for KIT-ML's 21)."""
    return 8 + (num_joints - 1) * 9 + 3 * num_joints


FEATURE_DIM = feature_dim(NUM_JOINTS)
ROOT_ROT_VELOCITY = slice(0, 1)
ROOT_LINEAR_VELOCITY = slice(1, 3)
ROOT_HEIGHT = slice(3, 4)
RIC = slice(4, 4 + (NUM_JOINTS - 1) * 3)
ROT6D = slice(RIC.stop, RIC.stop + (NUM_JOINTS - 1) * 6)
LOCAL_VELOCITY = slice(ROT6D.stop, ROT6D.stop + NUM_JOINTS * 3)
FOOT_CONTACT = slice(LOCAL_VELOCITY.stop, LOCAL_VELOCITY.stop + 4)


def normalize(features: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """``(x - Mean) / Std`` over the last axis: (..., 263) -> (..., 263)."""
    return (features - mean) / std


def denormalize(features: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """``x * Std + Mean`` over the last axis, the inverse of :func:`normalize`."""
    return features * std + mean


def _rotate_by_inverse(quaternion: torch.Tensor, vectors: torch.Tensor) -> torch.Tensor:
    """Rotate vectors (..., 3) by the inverse of unit quaternions (..., 4) (w, x, y, z): ``R^T v``."""
    matrix = quaternion_to_matrix(quaternion)
    return torch.einsum("...ji,...j->...i", matrix, vectors)


def recover_root_rotation_position(features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Root facing quaternion and root position from de-normalised features.

    Args:
        features: (..., T, D) de-normalised features (D >= 4).

    Returns:
        ``(quaternion, position)``: (..., T, 4) root yaw ``(cos th_t, 0, sin th_t, 0)`` with
        ``th_t = sum_{s<t} f_s[0]``, and (..., T, 3) root positions (XZ integrated from the
        velocities rotated by the inverse yaw, Y the stored height).
    """
    rot_velocity = features[..., 0]
    angle = torch.zeros_like(rot_velocity)
    angle[..., 1:] = rot_velocity[..., :-1]
    angle = torch.cumsum(angle, dim=-1)
    zero = torch.zeros_like(angle)
    quaternion = torch.stack([torch.cos(angle), zero, torch.sin(angle), zero], dim=-1)

    velocity = torch.zeros(*features.shape[:-1], 3, dtype=features.dtype, device=features.device)
    velocity[..., 1:, 0] = features[..., :-1, 1]
    velocity[..., 1:, 2] = features[..., :-1, 2]
    position = torch.cumsum(_rotate_by_inverse(quaternion, velocity), dim=-2)
    position[..., 1] = features[..., 3]
    return quaternion, position


def recover_from_ric(features: torch.Tensor, num_joints: int = NUM_JOINTS) -> torch.Tensor:
    """Joint positions from de-normalised features (the dataset's ``recover_from_ric``).

    Args:
        features: (..., T, D) de-normalised HumanML3D features, ``D = feature_dim(num_joints)``.
        num_joints: J (22 for HumanML3D).

    Returns:
        (..., T, J, 3) y-up joint positions in metres; joint 0 is the root.
    """
    expected = feature_dim(num_joints)
    if features.shape[-1] != expected:
        raise ValueError(
            f"expected (..., T, {expected}) features for {num_joints} joints, got {tuple(features.shape)}"
        )
    quaternion, root = recover_root_rotation_position(features)
    ric = features[..., 4 : 4 + (num_joints - 1) * 3].unflatten(-1, (num_joints - 1, 3))
    joints = _rotate_by_inverse(quaternion.unsqueeze(-2).expand(*ric.shape[:-1], 4), ric)
    offset = torch.zeros_like(root)
    offset[..., 0] = root[..., 0]
    offset[..., 2] = root[..., 2]
    joints = joints + offset.unsqueeze(-2)
    return torch.cat([root.unsqueeze(-2), joints], dim=-2)


def _yaw_matrix(angle: torch.Tensor) -> torch.Tensor:
    """Rotation about +Y by ``angle`` (...,) -> (..., 3, 3), acting on column vectors."""
    c, s = torch.cos(angle), torch.sin(angle)
    zero, one = torch.zeros_like(angle), torch.ones_like(angle)
    rows = [torch.stack([c, zero, s], -1), torch.stack([zero, one, zero], -1), torch.stack([-s, zero, c], -1)]
    return torch.stack(rows, dim=-2)


def facing_angle(joints: torch.Tensor, smooth_sigma: float = 20.0) -> torch.Tensor:
    """Heading ``psi_t = atan2(f_x, f_z)`` of the root as the dataset's inverse kinematics defines it.

    ``Skeleton.inverse_kinematics_np`` unpacks ``face_joint_indx = [2, 1, 17, 16]`` as
    ``l_hip, r_hip, sdr_r, sdr_l``, so its across vector is ``(p1 - p2) + (p17 - p16)`` (left-minus-right
    hips plus right-minus-left shoulders); ``forward = Y x across``, smoothed over time by a Gaussian
    (sigma 20 frames, ``mode='nearest'``, ``smooth_forward=True``). The real sample's root rotation
    velocities match this definition, not the anatomical one.

    Args:
        joints: (T, 22, 3) y-up positions.
        smooth_sigma: Gaussian sigma in frames (0: no smoothing).

    Returns:
        (T,) heading angles in radians.
    """
    from scipy.ndimage import gaussian_filter1d  # lazy: scipy only for this filter

    across = (joints[:, 1] - joints[:, 2]) + (joints[:, 17] - joints[:, 16])
    across = across / across.norm(dim=-1, keepdim=True)
    forward = torch.linalg.cross(torch.tensor([0.0, 1.0, 0.0], dtype=joints.dtype).expand_as(across), across)
    if smooth_sigma > 0:
        smoothed = gaussian_filter1d(forward.numpy(), smooth_sigma, axis=0, mode="nearest")
        forward = torch.from_numpy(smoothed).to(joints.dtype)
    return torch.atan2(forward[:, 0], forward[:, 2])


def canonicalize(joints: torch.Tensor) -> torch.Tensor:
    """Floor at y = 0, frame-0 root XZ at the origin, frame-0 heading along +Z: (T, 22, 3) -> (T, 22, 3)."""
    joints = joints.clone()
    joints[..., 1] -= joints[..., 1].min()
    joints[..., 0] -= joints[0, 0, 0].clone()
    joints[..., 2] -= joints[0, 0, 2].clone()
    return torch.einsum("ij,tkj->tki", _yaw_matrix(-facing_angle(joints)[0]), joints)


def joints_to_features(
    joints: torch.Tensor, rot6d: torch.Tensor | None = None, contact_threshold: float = 0.002
) -> torch.Tensor:
    """HumanML3D features from joint positions (the ``process_file`` steps after retargeting).

    The joints are first put on the floor, with the frame-0 root XZ at the origin and the frame-0
    heading (:func:`facing_angle`) along +Z, so that :func:`recover_from_ric` (which starts at heading
    0 and the origin) returns them.

    Args:
        joints: (T + 1, 22, 3) y-up positions in metres (already on the HumanML3D skeleton proportions).
        rot6d: (T + 1, 21, 6) local 6D rotations of joints 1..21; ``None`` writes the identity
            ``(1, 0, 0, 0, 1, 0)`` (the dataset's own come from its inverse kinematics, not done here).
        contact_threshold: squared per-frame foot displacement below which a foot is in contact.

    Returns:
        (T, 263) de-normalised features.
    """
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3) or joints.shape[0] < 2:
        raise ValueError(f"expected joints (T + 1 >= 2, {NUM_JOINTS}, 3), got {tuple(joints.shape)}")
    joints = canonicalize(joints)
    psi = facing_angle(joints)
    facing = _yaw_matrix(-psi)  # world -> facing frame, (T+1, 3, 3)
    rel = joints.clone()
    rel[..., 0] -= joints[:, :1, 0]
    rel[..., 2] -= joints[:, :1, 2]
    ric = torch.einsum("tij,tkj->tki", facing, rel)[:, 1:]  # (T+1, 21, 3)
    turn = torch.remainder(psi[1:] - psi[:-1] + torch.pi, 2 * torch.pi) - torch.pi
    rot_velocity = -turn / 2  # quaternion half-angle of r_rot[t+1] r_rot[t]^-1 about Y
    root_step = torch.einsum("tij,tj->ti", facing[1:], joints[1:, 0] - joints[:-1, 0])
    local_velocity = torch.einsum("tij,tkj->tki", facing[:-1], joints[1:] - joints[:-1])
    step = ((joints[1:] - joints[:-1]) ** 2).sum(-1)
    contacts = (step[:, [7, 10, 8, 11]] < contact_threshold).to(joints.dtype)
    if rot6d is None:
        rot6d = joints.new_tensor([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]).expand(joints.shape[0], NUM_JOINTS - 1, 6)
    parts = [
        rot_velocity[:, None],
        root_step[:, [0, 2]],
        joints[:-1, 0, 1:2],
        ric[:-1].flatten(1),
        rot6d[:-1].flatten(1),
        local_velocity.flatten(1),
        contacts,
    ]
    return torch.cat(parts, dim=-1)


def group_statistics(features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and Std of (N, 263) frames as ``cal_mean_variance.ipynb``: each group's Std is its mean.

    Groups: ``[0:1] [1:3] [3:4]`` ric, rot6d, local velocity, foot contact (the slices above).
    Returns (263,) ``Mean`` and ``Std``.
    """
    mean = features.mean(0)
    std = features.std(0, correction=0)
    groups = (ROOT_ROT_VELOCITY, ROOT_LINEAR_VELOCITY, ROOT_HEIGHT, RIC, ROT6D, LOCAL_VELOCITY, FOOT_CONTACT)
    for part in groups:
        std[part] = std[part].mean()
    return mean, std


# ----------------------------------------------------------------------------------------------- files
FEATURE_MAGNITUDE_LIMIT = 1e4
"""Largest |value| accepted in a feature or statistics file. Features are metres, metres per frame,
6D rotation entries and contact flags (|x| < 10 in the released data), and normalised features stay far
below this; a larger value is a wrong file, not a motion."""


class NonFiniteFeaturesError(DataFileError):
    """A feature file holds NaN or Inf. The released HumanML3D has two such motions, 007975 and its
    mirror M007975 (reported on the [HumanML3D] issue tracker); the data loader leaves them out."""


def _real_float32(array: np.ndarray, path: Path, what: str, axes: tuple[str, ...], error=DataFileError):
    """``array`` as float32 when it holds real numbers (not bool flags), all finite and within
    :data:`FEATURE_MAGNITUDE_LIMIT`."""
    if array.dtype.kind == "b":
        raise DataFileError(f"{path}: {what!r} must hold real numbers, got dtype {array.dtype}")
    check_real(array, str(path), what)
    with np.errstate(over="ignore"):  # beyond float32 becomes Inf, refused below
        array = array.astype(np.float32)
    check_finite(array, str(path), what, axes, error)
    return check_magnitude(array, FEATURE_MAGNITUDE_LIMIT, str(path), what, axes)


def read_feature_vector(path: str | PathLike[str], what: str) -> np.ndarray:
    """A (263,) float32 vector from a ``.npy`` file (statistics); ``what`` names it in errors.

    Raises:
        DatasetNotFoundError: no such file.
        DataFileError: not a real (263,) array, a NaN / Inf, or a value beyond the magnitude limit.

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "Mean.npy"
        >>> np.save(path, np.zeros(263))
        >>> vector = read_feature_vector(path, "Mean")
        >>> vector.shape, vector.dtype
        ((263,), dtype('float32'))
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetNotFoundError(f"{path}: missing HumanML3D {what}")
    array = load_npy(path)
    if array.shape != (FEATURE_DIM,):
        raise DataFileError(f"{path}: expected {what} of shape ({FEATURE_DIM},), got {array.shape}")
    return _real_float32(array, path, what, ("column",))


def read_statistics(root: str | PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(Mean, Std)`` (263,) float32 from ``ROOT/Mean.npy`` and ``ROOT/Std.npy``; finite, Std positive.

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> root = Path(tempfile.mkdtemp())
        >>> np.save(root / "Mean.npy", np.zeros(263))
        >>> np.save(root / "Std.npy", np.ones(263))
        >>> mean, std = read_statistics(root)
        >>> mean.shape, float(std.min())
        ((263,), 1.0)
        >>> np.save(root / "Std.npy", np.zeros(263))
        >>> read_statistics(root)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        skeleton_mamba.errors.DataFileError: ...Std.npy: Std must be positive, column 0 is 0.0
    """
    root = Path(root)
    mean = read_feature_vector(root / "Mean.npy", "Mean")
    std = read_feature_vector(root / "Std.npy", "Std")
    if not np.all(std > 0):
        column = int(np.argmin(std > 0))
        raise DataFileError(f"{root / 'Std.npy'}: Std must be positive, column {column} is {std[column]}")
    return mean, std


def check_features(array: np.ndarray, path: str | PathLike[str]) -> np.ndarray:
    """``array`` read from ``path`` as (T, 263) float32 HumanML3D features (T >= 1), checked.

    Raises:
        DataFileError: not a real-valued array of that shape, or a value beyond the magnitude limit.
        NonFiniteFeaturesError: a NaN / Inf (or a value beyond float32), naming its frame and column.
    """
    path = Path(path)
    if array.ndim != 2 or array.shape[1] != FEATURE_DIM or not len(array):
        raise DataFileError(f"{path}: expected HumanML3D features (T >= 1, {FEATURE_DIM}), got {array.shape}")
    return _real_float32(array, path, "features", ("frame", "column"), NonFiniteFeaturesError)


def read_features(path: str | PathLike[str]) -> np.ndarray:
    """A (T, 263) HumanML3D feature ``.npy`` as float32, checked by :func:`check_features`.

    Raises:
        FileNotFoundError: no such file; and the errors of :func:`check_features`.

    Examples:
        >>> import tempfile
        >>> import numpy as np
        >>> from pathlib import Path
        >>> path = Path(tempfile.mkdtemp()) / "000001.npy"
        >>> np.save(path, np.zeros((40, 263)))
        >>> features = read_features(path)
        >>> features.shape, features.dtype
        ((40, 263), dtype('float32'))
        >>> bad = np.zeros((40, 263))
        >>> bad[3, 7] = np.nan
        >>> np.save(path, bad)
        >>> read_features(path)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        skeleton_mamba.tasks.motion.formats.humanml3d_features.NonFiniteFeaturesError: ...000001.npy: ...
    """
    return check_features(load_npy(path), path)
