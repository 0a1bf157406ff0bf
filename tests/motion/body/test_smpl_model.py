"""SMPL body model from a user file (.npz, Python-2 chumpy pickles), blend skinning, safe loading."""

from __future__ import annotations

import pickle
import struct
import sys
import types

import numpy as np
import pytest
import scipy.sparse
import torch

from skeleton_mamba.skeletons import SMPL24
from skeleton_mamba.tasks.motion.body.smpl_model import SMPLModel, load_smpl_model
from skeleton_mamba.tasks.motion.io.safe_pickle import (
    ChumpyArray,
    SparseMatrix,
    UnsafePickleError,
    safe_load_pickle,
    safe_loads_pickle,
)
from tests.helpers.smpl import (
    BLENDED,
    rest_joint_positions,
    tiny_model_arrays,
    write_tiny_smpl_npz,
)


def rotation(axis, angle) -> np.ndarray:
    """Rodrigues' formula, written out (independent of the toolkit's kornia conversions)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def load_model_from(a: dict[str, np.ndarray]) -> SMPLModel:
    return SMPLModel(a["v_template"], a["shapedirs"], a["posedirs"], a["J_regressor"], a["weights"], a["f"])


def descendants(joint: int) -> set[int]:
    out = {joint}
    for j in range(24):
        if SMPL24.parents[j] in out:
            out.add(j)
    return out


# ---------------------------------------------------------------- Python-2 style pickles
class FakeCh:
    """What chumpy's ``Ch.__getstate__`` writes: its __dict__ without _parents/_cache."""

    __module__, __qualname__ = "chumpy.ch", "Ch"  # pickled by name as chumpy.ch.Ch (with py2_names)

    def __init__(self, x):
        self.x = np.asarray(x, dtype=np.float64)
        self._dirty_vars = {"x"}
        self._itr = None
        self._depends_on_deps = {}
        self._make_dense = False
        self._make_sparse = False


class FakeOldCSC:
    """scipy < 1.0's csc_matrix state (instance attribute ``format``)."""

    __module__, __qualname__ = "scipy.sparse.csc", "csc_matrix"

    def __init__(self, dense):
        m = scipy.sparse.csc_matrix(dense)
        self.format, self._shape, self.maxprint = "csc", m.shape, 50
        self.data, self.indices, self.indptr = m.data, m.indices, m.indptr


class Py2Pickler(pickle._Pickler):
    """Writes ``bytes`` and ``str`` as Python-2 ``str`` (SHORT_BINSTRING / BINSTRING), as Python 2 did."""

    dispatch = dict(pickle._Pickler.dispatch)

    def save_py2_str(self, obj):
        raw = obj if isinstance(obj, bytes) else obj.encode("latin1")
        if len(raw) < 256:
            self.write(pickle.SHORT_BINSTRING + bytes([len(raw)]) + raw)
        else:
            self.write(pickle.BINSTRING + struct.pack("<i", len(raw)) + raw)
        self.memoize(obj)

    dispatch[bytes] = save_py2_str
    dispatch[str] = save_py2_str


@pytest.fixture
def py2_names(monkeypatch):
    """Make FakeCh / FakeOldCSC pickle as 'chumpy.ch.Ch' and 'scipy.sparse.csc.csc_matrix'."""
    for cls, module, name in ((FakeCh, "chumpy.ch", "Ch"), (FakeOldCSC, "scipy.sparse.csc", "csc_matrix")):
        mod = types.ModuleType(module)
        setattr(mod, name, cls)
        monkeypatch.setitem(sys.modules, module, mod)
    monkeypatch.setitem(sys.modules, "chumpy", types.ModuleType("chumpy"))


def py2_pickle(value, protocol: int = 2) -> bytes:
    """A pickle as Python 2 + numpy 1 wrote it (py2 strings, numpy.core module names)."""
    import io

    buf = io.BytesIO()
    Py2Pickler(buf, protocol=protocol).dump(value)
    return buf.getvalue().replace(b"numpy._core.multiarray", b"numpy.core.multiarray")


def write_official_style_pickle(path, arrays):
    """The official SMPL layout: chumpy Ch arrays, a scipy CSC J_regressor, uint32 kintree_table."""
    data = dict(arrays)
    data["v_template"] = FakeCh(arrays["v_template"])
    data["shapedirs"] = FakeCh(arrays["shapedirs"])
    data["J_regressor"] = FakeOldCSC(arrays["J_regressor"])
    data["kintree_table"] = np.where(arrays["kintree_table"] < 0, 2**32 - 1, arrays["kintree_table"]).astype(
        np.uint32
    )
    data["bs_style"], data["bs_type"] = "lbs", "lrotmin"
    path.write_bytes(py2_pickle(data))
    return path


# ---------------------------------------------------------------- skinning
def test_zero_pose_returns_the_template():
    a = tiny_model_arrays()
    model = load_model_from(a)
    trans = torch.tensor([0.3, -0.1, 2.0], dtype=torch.float64)
    vertices, joints = model(torch.zeros(2, 72, dtype=torch.float64), trans=trans)
    assert vertices.numpy() == pytest.approx(np.broadcast_to(a["v_template"] + trans.numpy(), (2, 97, 3)))
    assert joints[0].numpy() == pytest.approx(rest_joint_positions() + trans.numpy(), abs=1e-12)


def test_shape_blend_shapes():
    a = tiny_model_arrays()
    model = load_model_from(a)
    betas = np.array([1.5, -2.0])  # fewer than the model's 3: the rest are zero
    vertices, joints = model(torch.zeros(24, 3, dtype=torch.float64), betas=torch.from_numpy(betas))
    shaped = a["v_template"] + a["shapedirs"][:, :, 0] * 1.5 - a["shapedirs"][:, :, 1] * 2.0
    assert vertices.numpy() == pytest.approx(shaped, abs=1e-12)
    assert joints.numpy() == pytest.approx(a["J_regressor"] @ shaped, abs=1e-12)
    with pytest.raises(ValueError, match="has 3 betas, got 4"):
        model(torch.zeros(24, 3), betas=torch.zeros(4))


def test_rotating_one_joint_rotates_its_vertices_about_it():
    a = tiny_model_arrays(pose_blend=False)
    model = load_model_from(a)
    elbow = 18  # left elbow; its subtree: elbow, wrist (20), hand (22)
    R = rotation([0.3, 1.0, -0.2], 1.1)
    poses = torch.zeros(24, 3, dtype=torch.float64)
    poses[elbow] = torch.from_numpy(np.array([0.3, 1.0, -0.2]) / np.linalg.norm([0.3, 1.0, -0.2]) * 1.1)
    vertices, joints = model(poses)
    v, j = a["v_template"], rest_joint_positions()
    moving = descendants(elbow)
    for k in range(24):
        group = slice(4 * k, 4 * k + 4)
        expected = (v[group] - j[elbow]) @ R.T + j[elbow] if k in moving else v[group]
        assert vertices[group].numpy() == pytest.approx(expected, abs=1e-12), k
        assert joints[k].numpy() == pytest.approx(
            R @ (j[k] - j[elbow]) + j[elbow] if k in moving else j[k], abs=1e-12
        )
    # the vertex weighted half to the (still) shoulder and half to the elbow: the mean of both transforms
    b = v[BLENDED]
    assert vertices[BLENDED].numpy() == pytest.approx(0.5 * b + 0.5 * (R @ (b - j[elbow]) + j[elbow]))


def test_root_orientation_and_translation():
    a = tiny_model_arrays(pose_blend=True)  # the root's rotation is not a pose-blend-shape feature
    model = load_model_from(a)
    R = rotation([0.0, 1.0, 0.0], 0.7)
    poses = torch.zeros(24, 3, dtype=torch.float64)
    poses[0, 1] = 0.7
    trans = np.array([1.0, 0.0, -2.0])
    vertices, _ = model(poses, trans=torch.from_numpy(trans))
    pelvis = rest_joint_positions()[0]
    assert vertices.numpy() == pytest.approx((a["v_template"] - pelvis) @ R.T + pelvis + trans, abs=1e-12)


def test_pose_blend_shapes_use_rotation_minus_identity():
    a = tiny_model_arrays(pose_blend=True)
    model = load_model_from(a)
    knee = 5  # right knee: not an ancestor of the pelvis vertices checked below
    R = rotation([1.0, 0.0, 0.0], 0.9)
    poses = torch.zeros(24, 3, dtype=torch.float64)
    poses[knee, 0] = 0.9
    vertices, _ = model(poses)
    feature = np.zeros(207)
    feature[9 * (knee - 1) : 9 * knee] = (R - np.eye(3)).ravel()  # row-major, joints 1..23
    offsets = np.einsum("vcp,p->vc", a["posedirs"], feature)
    pelvis = slice(0, 4)  # weighted to the unrotated pelvis: only the blend-shape offset moves them
    assert vertices[pelvis].numpy() == pytest.approx(a["v_template"][pelvis] + offsets[pelvis], abs=1e-12)
    assert np.abs(offsets[pelvis]).max() > 1e-3  # the check above is not trivially satisfied


# ---------------------------------------------------------------- files
def test_official_pickle_and_npz_give_the_same_model(tmp_path, py2_names):
    a = tiny_model_arrays()
    pkl = write_official_style_pickle(tmp_path / "basicModel_neutral_lbs_10_207_0_v1.0.0.pkl", a)
    raw = pkl.read_bytes()
    assert b"chumpy.ch\nCh" in raw and b"scipy.sparse.csc\ncsc_matrix" in raw and b"numpy.core" in raw
    loaded = safe_load_pickle(pkl, encoding="latin1")
    assert isinstance(loaded["v_template"], ChumpyArray) and isinstance(loaded["J_regressor"], SparseMatrix)
    assert np.asarray(loaded["J_regressor"]) == pytest.approx(a["J_regressor"])
    from_pkl = load_smpl_model(pkl)
    from_npz = load_smpl_model(write_tiny_smpl_npz(tmp_path / "SMPL_NEUTRAL.npz"))
    poses = torch.from_numpy(np.random.default_rng(1).normal(0, 0.4, (3, 24, 3)))
    v1, j1 = from_pkl(poses, betas=torch.tensor([0.5, 1.0, -1.0]))
    v2, j2 = from_npz(poses, betas=torch.tensor([0.5, 1.0, -1.0]))
    assert v1.numpy() == pytest.approx(v2.numpy(), abs=1e-12) and j1.numpy() == pytest.approx(j2.numpy())
    # the Python-2 strings need latin1: the default ASCII decoding refuses the array bytes
    with pytest.raises(UnsafePickleError, match="basicModel_neutral"):
        safe_load_pickle(pkl)


def test_stand_ins_from_protocol_0_and_modern_scipy(py2_names):
    ch = safe_loads_pickle(pickle.dumps(FakeCh(np.arange(6.0).reshape(2, 3)), protocol=0), encoding="latin1")
    assert isinstance(ch, ChumpyArray) and np.asarray(ch) == pytest.approx(np.arange(6.0).reshape(2, 3))
    dense = np.array([[0.0, 2.0, 0.0], [1.0, 0.0, 3.0]])
    sparse = scipy.sparse
    for matrix in (sparse.csr_matrix(dense), sparse.csc_matrix(dense), sparse.csc_array(dense)):
        restored = safe_loads_pickle(pickle.dumps(matrix, protocol=4))
        assert restored.format == matrix.format and np.asarray(restored) == pytest.approx(dense)


class _Exploit:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        import os

        return (os.system, (f"touch {self.marker}",))


def test_new_allowances_run_nothing(tmp_path, py2_names):
    marker = tmp_path / "pwned"
    evil = FakeCh(np.zeros(3))
    evil.payload = _Exploit(marker)  # a payload hidden in a Ch's state
    with pytest.raises(UnsafePickleError, match="refusing to unpickle global 'posix.system'"):
        safe_loads_pickle(py2_pickle({"v_template": evil}), "evil.pkl", encoding="latin1")
    assert not marker.exists()
    # other chumpy classes (computation graphs) are refused by name
    derived = py2_pickle({"x": FakeCh(np.zeros(2))}).replace(b"chumpy.ch\nCh", b"chumpy.ch_ops\nadd")
    with pytest.raises(UnsafePickleError, match="chumpy.ch_ops.add"):
        safe_loads_pickle(derived, encoding="latin1")
    # copy_reg._reconstructor builds the stand-ins only
    forged = b"ccopy_reg\n_reconstructor\n(ccollections\nOrderedDict\nc__builtin__\nobject\nNtR."
    with pytest.raises(UnsafePickleError, match="forged.pkl: not a readable data pickle.*stand-ins only"):
        safe_loads_pickle(forged, "forged.pkl")
    # a Ch without an array, an inconsistent sparse matrix
    bare = FakeCh(np.zeros(1))
    del bare.x
    with pytest.raises(UnsafePickleError, match="without its array 'x'"):
        safe_loads_pickle(py2_pickle(bare), encoding="latin1")
    bad = FakeOldCSC(np.eye(3))
    bad.indptr = np.array([0, 1, 5, 3])
    with pytest.raises(UnsafePickleError, match=r"inconsistent csc matrix of shape \(3, 3\)"):
        safe_loads_pickle(py2_pickle(bad), encoding="latin1")


def test_model_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="SMPL model file not found"):
        load_smpl_model(tmp_path / "missing.pkl")
    a = tiny_model_arrays()
    missing = dict(a)
    del missing["weights"]
    np.savez(tmp_path / "noweights.npz", **missing)
    with pytest.raises(ValueError, match=r"noweights.npz: not an SMPL model file: no 'weights'"):
        load_smpl_model(tmp_path / "noweights.npz")
    # a z-up model (the template rotated by +90 degrees about x) is not the toolkit's y-up SMPL
    z_up = dict(a, v_template=a["v_template"] @ rotation([1, 0, 0], np.pi / 2).T)
    np.savez(tmp_path / "zup.npz", **z_up)
    with pytest.raises(ValueError, match="zup.npz: the model's rest joints do not follow the y-up"):
        load_smpl_model(tmp_path / "zup.npz")
    # SMPL+H-like joint trees are refused
    tree = a["kintree_table"].copy()
    tree[0, 23] = 20
    np.savez(tmp_path / "tree.npz", **dict(a, kintree_table=tree))
    with pytest.raises(ValueError, match="tree.npz: the joint tree is not SMPL-24's"):
        load_smpl_model(tmp_path / "tree.npz")
    np.savez(tmp_path / "shape.npz", **dict(a, posedirs=a["posedirs"][..., :10]))
    with pytest.raises(ValueError, match=r"'posedirs' has shape \(97, 3, 10\)"):
        load_smpl_model(tmp_path / "shape.npz")
    # an npz holding a pickled object (a sparse regressor saved as an object array)
    np.savez(tmp_path / "obj.npz", **dict(a, J_regressor=np.array(scipy.sparse.csc_matrix(a["J_regressor"]))))
    with pytest.raises(ValueError, match="obj.npz: unreadable SMPL .npz without pickles"):
        load_smpl_model(tmp_path / "obj.npz")
