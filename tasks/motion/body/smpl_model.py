"""The SMPL body model ([SMPL]) from a user-supplied model file, in torch.

The model file is NOT distributed with the project (its licence forbids it); users pass its path:

* the official pickles ``SMPL_NEUTRAL.pkl`` / ``basicModel_{f,m}_lbs_10_207_0_v1.0.0.pkl`` (Python-2 pickles
  holding chumpy ``Ch`` arrays and a scipy.sparse ``J_regressor``), read with the project's restricted
  unpickler (:func:`~skeleton_mamba.tasks.motion.io.safe_pickle.safe_load_pickle`, ``encoding="latin1"``):
  neither chumpy nor scipy is needed and nothing from the file is executed;
* the ``.npz`` conversions (smplx layout) with the same keys.

Keys used: ``v_template`` (V, 3), ``shapedirs`` (V, 3, B), ``posedirs`` (V, 3, 207), ``J_regressor``
(24, V), ``weights`` (V, 24), ``kintree_table`` (2, 24) (row 0: parent of each joint, the root's is -1 or
2^32 - 1), ``f`` (F, 3).

Linear blend skinning (SMPL paper, Eqs. 1-10), with ``R_k`` the local joint rotations of axis-angle ``pose``::

    v_shaped = v_template + shapedirs . betas                  shape blend shapes B_S
    J        = J_regressor @ v_shaped                          rest joints (24, 3)
    v_posed  = v_shaped + posedirs . vec(R_1..23 - I)          pose blend shapes B_P ("lrotmin", row-major)
    G_k      = world rotation / position of joint k by forward kinematics of (R, J) with the root at J_0
    v        = sum_k w_vk (G_k.R (v_posed - J_k) + G_k.p) + trans

The model's joint tree must be SMPL-24's (:data:`skeleton_mamba.skeletons.SMPL24` parents) and its rest
joints must follow the toolkit's y-up convention of :mod:`.smpl` (AIST++ SMPL: +y up, +z forward, +x the
body's left); the loader checks both against :data:`~.smpl.SMPL_REST_OFFSETS`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.body.kinematics import forward_kinematics
from skeleton_mamba.tasks.motion.body.rotations import axis_angle_to_matrix
from skeleton_mamba.tasks.motion.body.smpl import SMPL_REST_OFFSETS
from skeleton_mamba.tasks.motion.io.safe_pickle import SparseMatrix, safe_load_pickle

__all__ = ["SMPLModel", "load_smpl_model", "MODEL_KEYS"]

MODEL_KEYS = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f")
NUM_JOINTS = 24
POSE_FEATURES = 9 * (NUM_JOINTS - 1)  # 207
# A model file whose rest bones point, on average, less along the toolkit's rest offsets than this
# cosine is not y-up SMPL-24 (a z-up model gives about 0.3; an SMPL file about 0.99).
MIN_REST_COSINE = 0.8
MAX_DENSE_ENTRIES = 10**8  # a sparse regressor larger than this when dense is not an SMPL file


class SMPLModel(torch.nn.Module):
    """SMPL linear blend skinning (module docstring); arrays become buffers (``.to()`` moves them).

    Args:
        v_template: (V, 3) template vertices, metres, y-up.
        shapedirs: (V, 3, B) shape blend shapes.
        posedirs: (V, 3, 207) pose blend shapes.
        J_regressor: (24, V) joint regressor (dense).
        weights: (V, 24) skinning weights.
        faces: (F, 3) triangle vertex indices.
        source: the file the model came from (error messages, metadata).
    """

    def __init__(
        self,
        v_template: np.ndarray,
        shapedirs: np.ndarray,
        posedirs: np.ndarray,
        J_regressor: np.ndarray,
        weights: np.ndarray,
        faces: np.ndarray,
        source: str = "",
    ) -> None:
        super().__init__()
        num_vertices = len(v_template)
        self.source = source
        self.register_buffer("v_template", torch.as_tensor(v_template, dtype=torch.float64))
        self.register_buffer("shapedirs", torch.as_tensor(shapedirs, dtype=torch.float64))
        # (207, V * 3): pose features times this matrix give the flattened vertex offsets
        flat = torch.as_tensor(posedirs, dtype=torch.float64).reshape(num_vertices * 3, POSE_FEATURES)
        self.register_buffer("posedirs", flat.T.contiguous())
        self.register_buffer("J_regressor", torch.as_tensor(J_regressor, dtype=torch.float64))
        self.register_buffer("weights", torch.as_tensor(weights, dtype=torch.float64))
        self.register_buffer("faces", torch.as_tensor(np.asarray(faces, dtype=np.int64)))

    @property
    def num_vertices(self) -> int:
        return self.v_template.shape[0]

    @property
    def num_betas(self) -> int:
        return self.shapedirs.shape[-1]

    def rest_joints(self, betas: torch.Tensor | None = None) -> torch.Tensor:
        """(..., 24, 3) rest-pose joints ``J_regressor @ v_shaped(betas)``."""
        return torch.einsum("jv,...vc->...jc", self.J_regressor, self.shaped_vertices(betas))

    def shaped_vertices(self, betas: torch.Tensor | None = None) -> torch.Tensor:
        """(..., V, 3) template plus shape blend shapes for betas (..., B') with B' <= B (zero-padded)."""
        if betas is None:
            return self.v_template
        betas = betas.to(self.v_template)
        if betas.shape[-1] > self.num_betas:
            raise ValueError(f"{self.source}: the model has {self.num_betas} betas, got {betas.shape[-1]}")
        dirs = self.shapedirs[..., : betas.shape[-1]]
        return self.v_template + torch.einsum("vcb,...b->...vc", dirs, betas)

    def forward(
        self,
        poses: torch.Tensor,
        betas: torch.Tensor | None = None,
        trans: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Posed vertices and joints.

        Args:
            poses: (..., 24, 3) or (..., 72) axis-angle local rotations (joint 0 = global orientation).
            betas: (..., B') shape coefficients (B' <= B), default zeros (the mean shape).
            trans: (..., 3) translation added to everything (AIST++ ``smpl_trans / smpl_scaling``).

        Returns:
            ``(vertices, joints)``: (..., V, 3) and (..., 24, 3), float64 (the dtype of the buffers).
        """
        if poses.shape[-1] == 3 * NUM_JOINTS:
            poses = poses.reshape(*poses.shape[:-1], NUM_JOINTS, 3)
        if poses.shape[-2:] != (NUM_JOINTS, 3):
            raise ValueError(f"SMPL poses must be (..., 24, 3) or (..., 72), got {tuple(poses.shape)}")
        rot = axis_angle_to_matrix(poses.to(self.v_template))  # (..., 24, 3, 3)
        v_shaped = self.shaped_vertices(betas)  # (V, 3) or (..., V, 3)
        rest = torch.einsum("jv,...vc->...jc", self.J_regressor, v_shaped)  # (..., 24, 3)
        eye = torch.eye(3, dtype=rot.dtype, device=rot.device)
        features = (rot[..., 1:, :, :] - eye).flatten(-3)  # (..., 207), row-major per joint
        v_posed = v_shaped + (features @ self.posedirs).unflatten(-1, (self.num_vertices, 3))
        parents = torch.tensor(SMPL24.parents, device=rest.device).clamp(min=0)
        offsets = rest - rest[..., parents, :]  # (..., 24, 3); the root's is ignored by FK
        joints, world = forward_kinematics(rot, rest[..., 0, :], offsets, SMPL24.parents)
        # A_k x = G_k.R (x - J_k) + G_k.p, blended per vertex: M_v = sum_k w_vk A_k (3 x 4)
        shift = joints - (world @ rest.expand_as(joints)[..., None])[..., 0]  # (..., 24, 3)
        transforms = torch.cat([world, shift[..., None]], dim=-1).flatten(-2)  # (..., 24, 12)
        blended = (self.weights @ transforms).unflatten(-1, (3, 4))  # (..., V, 3, 4)
        vertices = (blended[..., :3] @ v_posed[..., None])[..., 0] + blended[..., 3]
        if trans is not None:
            trans = trans.to(vertices)[..., None, :]
            vertices, joints = vertices + trans, joints + trans
        return vertices, joints


def _array(data: dict, key: str, path: Path) -> np.ndarray:
    if key not in data:
        raise ValueError(f"{path}: not an SMPL model file: no '{key}' (needs {', '.join(MODEL_KEYS)})")
    value = data[key]
    if isinstance(value, SparseMatrix) and value.shape[0] * value.shape[1] > MAX_DENSE_ENTRIES:
        raise ValueError(f"{path}: '{key}' is a sparse matrix of implausible shape {value.shape}")
    try:
        return np.asarray(value)  # chumpy / scipy.sparse stand-ins convert through __array__
    except (TypeError, ValueError, AttributeError) as err:
        raise ValueError(f"{path}: '{key}' is not an array ({err})") from err


def _read(path: Path) -> dict:
    if path.suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as data:
                return {k: data[k] for k in data.files}
        except ValueError as err:  # e.g. an object array (a pickled sparse matrix) inside the npz
            raise ValueError(f"{path}: unreadable SMPL .npz without pickles ({err})") from err
    data = safe_load_pickle(path, encoding="latin1")
    if not isinstance(data, dict):
        raise ValueError(f"{path}: an SMPL model pickle holds a dict, got {type(data).__name__}")
    return data


def _check_rest_joints(rest: np.ndarray, path: Path) -> None:
    """Raise unless the rest bones point like the toolkit's y-up SMPL rest offsets."""
    parents = np.array(SMPL24.parents[1:])
    bones = rest[1:] - rest[parents]
    table = np.asarray(SMPL_REST_OFFSETS)[1:]
    cos = np.einsum("ij,ij->i", bones, table) / (
        np.linalg.norm(bones, axis=1) * np.linalg.norm(table, axis=1) + 1e-12
    )
    if cos.mean() < MIN_REST_COSINE:
        raise ValueError(
            f"{path}: the model's rest joints do not follow the y-up SMPL convention of the toolkit "
            f"(mean cosine {cos.mean():.2f} with the rest offsets of tasks/motion/body/smpl.py; "
            "is the model z-up or not SMPL?)"
        )


def load_smpl_model(path: str | Path) -> SMPLModel:
    """Load an SMPL model file (official ``.pkl`` or ``.npz`` conversion; module docstring).

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: a key is missing, a shape is wrong, the joint tree is not SMPL-24's or the rest
            joints are not y-up (the message names the file).
        UnsafePickleError: the pickle names a global outside the restricted unpickler's allow-list.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"SMPL model file not found: {path}")
    data = _read(path)
    arrays = {k: _array(data, k, path) for k in MODEL_KEYS}
    v_template = arrays["v_template"]
    num_vertices = len(v_template)
    expected = {
        "v_template": (num_vertices, 3),
        "posedirs": (num_vertices, 3, POSE_FEATURES),
        "J_regressor": (NUM_JOINTS, num_vertices),
        "weights": (num_vertices, NUM_JOINTS),
        "kintree_table": (2, NUM_JOINTS),
    }
    for key, shape in expected.items():
        if arrays[key].shape != shape:
            raise ValueError(f"{path}: '{key}' has shape {arrays[key].shape}, expected {shape} for SMPL-24")
    if arrays["shapedirs"].ndim != 3 or arrays["shapedirs"].shape[:2] != (num_vertices, 3):
        raise ValueError(f"{path}: 'shapedirs' has shape {arrays['shapedirs'].shape}, expected (V, 3, B)")
    faces = arrays["f"]
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= num_vertices:
        raise ValueError(f"{path}: 'f' must be (F, 3) vertex indices below {num_vertices}")
    kintree = arrays["kintree_table"].astype(np.int64)
    parents = np.where(kintree[0] >= 2**31 - 1, -1, kintree[0])  # uint32 -1 in the official files
    if not np.array_equal(kintree[1], np.arange(NUM_JOINTS)) or tuple(parents) != SMPL24.parents:
        raise ValueError(f"{path}: the joint tree is not SMPL-24's (kintree_table {kintree.tolist()})")
    rest = arrays["J_regressor"].astype(np.float64) @ v_template.astype(np.float64)
    _check_rest_joints(rest, path)
    return SMPLModel(
        v_template,
        arrays["shapedirs"],
        arrays["posedirs"],
        arrays["J_regressor"],
        arrays["weights"],
        faces,
        source=str(path),
    )
