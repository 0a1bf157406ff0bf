"""ONNX and torch.export of the backbone: the sequence forward and the causal streaming step.

Every exported graph is compared with eager PyTorch (an independent execution of the same module:
onnxruntime's kernels, or the ATen graph torch.export traced); the tensor-only SSD form used inside
exported graphs is compared with the float64 recurrence. Small random configs; the machine needs no GPU.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.skeletons import SKELETONS
from skeleton_mamba.ssd.exportable import ssd_exportable
from skeleton_mamba.ssd.recurrence import ssd_recurrence
from skeleton_mamba.tasks.training import onnx_export
from skeleton_mamba.tasks.training.cli import main as sm

TOL = 1e-4  # fp32, max abs difference


def tiny(skeleton: str, causal: bool) -> SkeletonMamba:
    torch.manual_seed(0)
    groups = len(SKELETONS[skeleton].groups)
    cfg = SkeletonMambaConfig(
        skeleton=skeleton, in_channels=3, dim=16, depth=1, heads=2, mlp_dim=32, causal=causal,
        group_paths=[list(range(groups))], mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16),
    )  # fmt: skip
    return SkeletonMamba(cfg).eval()


def padded(batch: int, frames: int, joints: int) -> tuple[torch.Tensor, torch.Tensor]:
    x = torch.randn(batch, frames, joints, 3)
    mask = torch.ones(batch, frames, dtype=torch.bool)
    mask[1, frames - frames // 3 :] = False
    return x, mask


@pytest.mark.parametrize("G", [1, 2])
def test_exportable_ssd_matches_the_float64_recurrence(G):
    torch.manual_seed(1)
    b, L, H, P, N = 2, 37, 4, 3, 5
    f64 = dict(dtype=torch.float64)
    x, dt = torch.randn(b, L, H, P, **f64), torch.randn(b, L, H, **f64)
    A, D = -torch.rand(H, **f64) * 4, torch.randn(H, **f64)
    B, C = torch.randn(b, L, G, N, **f64), torch.randn(b, L, G, N, **f64)
    kw = dict(D=D, dt_bias=torch.randn(H, **f64), initial_state=torch.randn(b, H, P, N, **f64))
    y, final = ssd_exportable(x, dt, A, B, C, return_final_state=True, **kw)
    y_ref, final_ref = ssd_recurrence(x, dt, A, B, C, return_final_state=True, **kw)
    torch.testing.assert_close(y, y_ref, rtol=0, atol=1e-12)
    torch.testing.assert_close(final, final_ref, rtol=0, atol=1e-12)


# Strict export takes about half a minute a skeleton on 2 cores: one skeleton in CI, all under -m slow.
@pytest.mark.parametrize(
    "skeleton",
    [s if s == "smpl24" else pytest.param(s, marks=pytest.mark.slow) for s in sorted(SKELETONS)],
)
def test_sequence_graph_matches_eager_for_every_skeleton(skeleton, tmp_path):
    model = tiny(skeleton, causal=False)
    spec = onnx_export.sequence_spec(model, batch=2, frames=12)
    program = onnx_export.export_program(spec, strict=True)
    path = onnx_export.export_onnx(spec, tmp_path / "sequence.onnx", program)
    j = model.skeleton.num_joints
    for batch, frames in ((2, 12), (3, 41)):  # two lengths (and another batch), padding masks
        x, mask = padded(batch, frames, j)
        with torch.no_grad():
            eager = model(x, mask)
            traced = program.module()(x, mask)
        (ours,) = onnx_export.run_onnx(path, {"x": x, "mask": mask})
        assert ours.shape == tuple(eager.shape)
        assert np.abs(ours - eager.numpy()).max() <= TOL
        assert (traced - eager).abs().max() <= TOL


def test_step_graph_stepped_300_frames_equals_the_causal_forward(tmp_path):
    model = tiny("ntu25", causal=True)
    spec = onnx_export.step_spec(model, batch=2)
    program = onnx_export.export_program(spec, strict=True)
    path = onnx_export.export_onnx(spec, tmp_path / "step.onnx", program)
    frames, batch = 300, 3  # another batch than the example's: the batch is dynamic
    x = torch.randn(batch, frames, 25, 3)
    with torch.no_grad():
        full = model(x)  # the causal sequence forward
    states = onnx_export.zero_states(model, batch)
    traced_states = list(states)
    names = spec.input_names[1:]
    worst = traced_worst = 0.0
    with torch.no_grad():
        for t in range(frames):
            y, *nxt = onnx_export.run_onnx(path, {"x": x[:, t], **dict(zip(names, states))})
            states = [torch.from_numpy(s) for s in nxt]
            worst = max(worst, float(np.abs(y - full[:, t].numpy()).max()))
            if t < 20:  # the torch.export graph on the first frames (eager-speed ATen, slower per call)
                y_t, *traced_states = program.module()(x[:, t], *traced_states)
                traced_worst = max(traced_worst, float((y_t - full[:, t]).abs().max()))
    assert worst <= TOL
    assert traced_worst <= TOL


def test_step_graph_refuses_a_bidirectional_backbone():
    with pytest.raises(Exception, match="causal"):
        onnx_export.step_spec(tiny("ntu25", causal=False))


def test_export_onnx_command_bad_backbone_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("dim: [unclosed\n")
    assert sm(["export-onnx", "--backbone", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bad) in err
