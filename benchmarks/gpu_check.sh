#!/usr/bin/env bash
# The GPU check, in one run on a CUDA machine that reaches only the package registry (under 8 minutes):
#   1. a virtual environment with the CUDA build of torch, the project, and mamba-ssm's Triton SSD path
#      (installed without building its CUDA extensions: the Triton kernels need none of them);
#   2. the CUDA tests: the Triton kernel equals the pure-PyTorch SSD (forward and backward) and the backbone
#      on the kernel equals the pure-PyTorch backbone (tests/backbone/test_gpu.py, tests/backbone/test_ssd.py);
#   3. EMM 1000-step DDPM sampling at the paper's size ([EgoMusic] supp. Table 2, one 150-frame sample, no
#      classifier-free guidance) against the EDGE-style transformer twin of equal size, beside the figures
#      [EgoMusic] reports (24.8 s for EMM, 30.1 s for EDGE).
#
#   bash benchmarks/gpu_check.sh              # results: benchmarks/gpu_check_results.json (or $OUT/)
#
# Settings (environment): GPU_CHECK_PYTHON (the interpreter to build the venv from, default python3),
# GPU_CHECK_VENV (default .venv-gpu), TORCH_SPEC (default torch==2.13.0: PyPI's Linux wheel is a CUDA build).
# Exit codes: 0 done, 3 no CUDA GPU on this machine (nothing installed or run), other: the failing step's.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
PY=${GPU_CHECK_PYTHON:-python3}
VENV=${GPU_CHECK_VENV:-.venv-gpu}
RESULTS=${OUT:-benchmarks}/gpu_check_results.json
step() { echo "[gpu_check $(( $(date +%s) - start )) s] $*"; }

gpu_present() {
    if command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L 2>/dev/null | grep -q "^GPU"; then
        return 0
    fi
    "$PY" -c "import sys, torch; sys.exit(0 if torch.cuda.is_available() else 1)" >/dev/null 2>&1
}

if ! gpu_present; then
    echo "gpu_check: no CUDA GPU is present on this machine (no GPU listed by nvidia-smi, and" \
         "torch.cuda.is_available() is False for $PY): nothing was installed or run." >&2
    exit 3
fi
command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L

step "virtual environment $VENV"
[ -d "$VENV" ] || "$PY" -m venv "$VENV"
# shellcheck disable=SC1091
. "$VENV/bin/activate"
python -m pip install -q --upgrade pip
python -m pip install -q "${TORCH_SPEC:-torch==2.13.0}"
python -m pip install -q -e ".[dev]"
# mamba-ssm's Triton SSD path only: no compiled extensions (MAMBA_SKIP_CUDA_BUILD), no optional
# dependencies (its Mamba-3 kernels pull tilelang and quack); einops, packaging and triton come with the
# project and torch. skeleton_mamba.ssd.kernel loads the Triton modules without the package __init__,
# which imports the Mamba-1 extension.
MAMBA_SKIP_CUDA_BUILD=TRUE python -m pip install -q --no-deps --no-build-isolation "mamba-ssm>=2.3.0"
python - <<'EOF'
import torch
from skeleton_mamba.ssd.kernel import import_triton_ssd
import_triton_ssd()
print(f"torch {torch.__version__}, CUDA {torch.version.cuda}, {torch.cuda.get_device_name()}: "
      "mamba-ssm Triton SSD imported")
EOF

step "CUDA tests (kernel path vs pure-PyTorch path)"
python -m pytest -q -p no:xdist -rs tests/backbone/test_gpu.py tests/backbone/test_ssd.py -k "gpu or kernel or cuda"

step "EMM vs EDGE-style twin: 1000-step DDPM at the paper's size"
python benchmarks/bench_egodance.py --size paper --no-train --ddpm-run --step-repeats 5 --json > "$RESULTS.tmp"
mv "$RESULTS.tmp" "$RESULTS"
python - "$RESULTS" <<'EOF'
import json
import sys

result = json.load(open(sys.argv[1]))
paper = {"emm_skeleton_mamba": 24.8, "edge_transformer": 30.1}  # [EgoMusic]: seconds per sample
print(f"{'model':<20} {'params':>11} {'step ms':>9} {'DDPM-1000 s':>12} {'paper s':>8}")
for name, r in result["models"].items():
    print(f"{name:<20} {r['denoiser_params']:>11,} {r['sample_step_ms']:>9.1f} "
          f"{r['ddpm1000_wall_s']:>12.2f} {paper[name]:>8.1f}")
EOF
step "done; results in $RESULTS"
