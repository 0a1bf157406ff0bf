"""The GPU path: mamba-ssm's Triton kernel against the pure-PyTorch SSD, and the GPU check script.

The CUDA tests run where a CUDA device and mamba-ssm are present (``benchmarks/gpu_check.sh`` installs
mamba-ssm's Triton path and runs them); everywhere else they skip with the reason. The import of the
Triton modules from an install without mamba-ssm's compiled extensions, and the check script's behaviour
on a machine without a GPU, are tested on any machine.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from skeleton_mamba import MixerConfig, SkeletonMamba, SkeletonMambaConfig
from skeleton_mamba.ssd import kernel as kernel_mod
from skeleton_mamba.ssd import ssd

REPO = Path(__file__).resolve().parents[2]


def write_fake_package(root: Path) -> None:
    """A ``mamba_ssm`` laid out as an install without compiled extensions: its ``__init__`` imports the
    missing ``selective_scan_cuda``; the Triton module is a plain-PyTorch stand-in."""
    triton = root / "mamba_ssm" / "ops" / "triton"
    triton.mkdir(parents=True)
    (root / "mamba_ssm" / "__init__.py").write_text("import selective_scan_cuda  # not built\n")
    (root / "mamba_ssm" / "ops" / "__init__.py").write_text("")
    (triton / "__init__.py").write_text("")
    (triton / "ssd_combined.py").write_text("LOADED_WITHOUT_PACKAGE_INIT = True\n")


def test_triton_modules_import_without_compiled_extensions(tmp_path, monkeypatch):
    write_fake_package(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in [m for m in sys.modules if m.startswith("mamba_ssm")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.raises(ImportError, match="selective_scan_cuda"):
        __import__("mamba_ssm")
    module = kernel_mod.import_triton_ssd()
    assert module.LOADED_WITHOUT_PACKAGE_INIT is True
    assert sys.modules["mamba_ssm"].__path__ == [str(tmp_path / "mamba_ssm")]
    # Once registered, the bare package is still found: "auto" keeps choosing the kernel on CUDA after
    # its first call (on an H200, every later call had fallen back to the PyTorch SSD).
    assert kernel_mod.mamba_ssm_installed()
    monkeypatch.setattr(kernel_mod, "is_cuda", lambda t: True)
    assert kernel_mod.kernel_available(torch.zeros(1)) and kernel_mod.import_triton_ssd() is module
    for name in [m for m in sys.modules if m.startswith("mamba_ssm")]:
        del sys.modules[name]


def test_other_import_errors_are_not_hidden(tmp_path, monkeypatch):
    (tmp_path / "mamba_ssm").mkdir()
    (tmp_path / "mamba_ssm" / "__init__.py").write_text("import triton_is_missing_here\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in [m for m in sys.modules if m.startswith("mamba_ssm")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.raises(ImportError, match="triton_is_missing_here"):
        kernel_mod.import_triton_ssd()
    for name in [m for m in sys.modules if m.startswith("mamba_ssm")]:
        del sys.modules[name]


def test_gpu_check_says_when_no_gpu_is_present(tmp_path):
    """On a machine without CUDA the script stops at once, says so, and installs nothing."""
    if torch.cuda.is_available():
        pytest.skip("a CUDA device is present: the script would run the real check")
    env = {**os.environ, "GPU_CHECK_PYTHON": sys.executable, "GPU_CHECK_VENV": str(tmp_path / "venv")}
    out = subprocess.run(
        ["bash", str(REPO / "benchmarks" / "gpu_check.sh")],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert out.returncode == 3, out.stdout + out.stderr
    assert "no CUDA GPU" in out.stderr
    assert not (tmp_path / "venv").exists()


def cuda_kernel_or_skip() -> None:
    if not torch.cuda.is_available():
        pytest.skip("no CUDA device: the mamba-ssm Triton kernel runs on CUDA only")
    if not kernel_mod.mamba_ssm_installed():
        pytest.skip("mamba-ssm is not installed (benchmarks/gpu_check.sh installs its Triton path)")


def test_kernel_equals_pure_pytorch_ssd_forward_and_backward():
    cuda_kernel_or_skip()
    g = torch.Generator().manual_seed(0)
    b, T, h, p, n = 2, 300, 4, 32, 16
    inp = dict(
        x=torch.randn(b, T, h, p, generator=g),
        dt=torch.randn(b, T, h, generator=g),
        A=-torch.rand(h, generator=g) * 8 - 1,
        B=torch.randn(b, T, 1, n, generator=g),
        C=torch.randn(b, T, 1, n, generator=g),
        D=torch.ones(h),
        dt_bias=torch.full((h,), -2.0),
    )
    results = {}
    for impl in ("kernel", "chunked"):
        leaves = {k: v.cuda().requires_grad_(True) for k, v in inp.items()}
        y = ssd(**leaves, impl=impl, chunk_size=64)
        y.square().sum().backward()
        results[impl] = (y.detach(), {k: v.grad for k, v in leaves.items()})
    (y_k, g_k), (y_t, g_t) = results["kernel"], results["chunked"]
    tol = kernel_mod.KERNEL_TF32_ERROR  # the kernel's products are TF32
    assert (y_k - y_t).abs().max() <= tol * y_t.abs().max()
    for name in inp:
        assert (g_k[name] - g_t[name]).abs().max() <= tol * g_t[name].abs().max(), name


def test_backbone_on_the_kernel_equals_the_pure_pytorch_backbone():
    cuda_kernel_or_skip()
    torch.manual_seed(0)

    def config(use_kernel: bool) -> SkeletonMambaConfig:
        return SkeletonMambaConfig(
            skeleton="smpl24",
            in_channels=9,
            dim=32,
            depth=2,
            mlp_dim=64,
            mixer=MixerConfig(headdim=16, d_state=16, use_kernel=use_kernel),
        )

    fast = SkeletonMamba(config(True)).cuda()
    plain = SkeletonMamba(config(False)).cuda()
    plain.load_state_dict(fast.state_dict())
    x = torch.randn(2, 150, 24, 9, device="cuda")
    y_fast, y_plain = fast(x), plain(x)
    assert (y_fast - y_plain).abs().max() <= kernel_mod.KERNEL_TF32_ERROR * y_plain.abs().max()
