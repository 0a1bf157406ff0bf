"""Compiled inference: ``torch.compile`` (inductor) with the weights frozen into the graph.

On a CPU most of a Skeleton Mamba step that is not a matrix product is element-wise work on small
tensors (the Group Scan's 40-token path sequences: causal convolution taps, SiLU, gated RMSNorm, decay
masks, layout copies), each a separate PyTorch operation that reads and writes its whole input.
Inductor fuses chains of them into single loops, and with ``freezing`` it treats the parameters as
constants: it folds what depends only on them (e.g. ``-exp(A_log)``) and prepacks the weights of the
matrix products for oneDNN. :func:`compile_for_inference` compiles any module or function so (the EMM
denoiser: ``tasks/egodance/sampling.py``, ``CompiledDenoiser``); frozen means frozen: the compiled
function keeps the parameter values of its first call.

The frame step of a causal SkeletonMamba:

At the paper width a frame (:func:`skeleton_mamba.runtime.streaming.step`) is a few hundred small operators
(projections of 5 to 40 tokens, the frame-wise scans, the SSD state update): on a CPU its time goes to
launching them, not to arithmetic. :class:`CompiledStep` compiles the whole frame,
:func:`~skeleton_mamba.runtime.streaming.frame_forward` (input projection, every block's
:func:`~skeleton_mamba.runtime.streaming.block_step`, output), into one inductor graph with the weights
frozen: inductor treats them as constants, folds what depends on them alone, prepacks the
projections for oneDNN and fuses the element-wise operators into C++ loops.

- Same results as :func:`~skeleton_mamba.runtime.streaming.step` to the rounding of the compute dtype (fp32:
  a few 1e-6 at the paper width), the same :class:`~skeleton_mamba.runtime.streaming.StreamState` (layout
  unchanged, updated in place: the compiled graph writes the new convolution and SSD states back
  into the state's tensors).
- Compiling happens on the first call. It needs a C++ compiler (inductor's CPU backend) and takes
  minutes of CPU at the paper width (``benchmarks/README.md``, "Compiled EMM sampling"); inductor keeps the
  compiled graph and kernels on disk (``TORCHINDUCTOR_CACHE_DIR``, default ``/tmp/torchinductor_$USER``),
  so the next time is faster.
- The graph is specialised to the input signature: batch size, dtype, device, the context's shape,
  and whether the tensors are inference tensors (made under ``torch.inference_mode``) or not: make the
  frames and the state the same way as for the first call. A new signature compiles again. After
  ``torch._dynamo.config.recompile_limit`` signatures (8 by default, per :class:`CompiledStep`) the
  call raises a RuntimeError, where dynamo's default would run eagerly from then on without saying so.
- The weights are copied into the graph: a change of any parameter or buffer after compiling (a
  ``load_state_dict``, a training step) makes the call raise; build a new :class:`CompiledStep`.
- Inference only, ``torch.inference_mode`` inside, as :func:`~skeleton_mamba.runtime.streaming.step`.
"""

from __future__ import annotations

import time
import types
import warnings
from collections.abc import Callable

import torch
from torch import nn

from skeleton_mamba.runtime import streaming
from skeleton_mamba.runtime.streaming import StreamState

__all__ = ["CompiledStep", "compile_for_inference", "compile_step_or_eager", "inductor_unavailable"]


def compile_for_inference(
    fn: Callable, *, freezing: bool = True, mode: str | None = None, fullgraph: bool = True
) -> Callable:
    """``torch.compile(fn)`` for inference on the inductor backend.

    Args:
        fn: the function; the modules it reads (by closure or attribute) are traced with it.
        freezing: treat the parameters and buffers as constants (inductor's ``freezing``; the weights
            must not change afterwards). Only valid when ``fn`` runs under ``torch.no_grad`` or
            ``torch.inference_mode``.
        mode: ``torch.compile``'s mode (``None``: default; e.g. ``"max-autotune-no-cudagraphs"``).
        fullgraph: the whole function must form one graph (a graph break raises instead of running
            part of it eagerly).

    Shapes are static (``dynamic=False``: a new shape compiles again).

    Freezing is set in inductor's configuration around every call (compiling happens inside the call),
    not as a ``torch.compile`` option: passed as an option (torch 2.13) it has no effect, the weights
    stay inputs of the graph and its matrix products plain ``mm`` on them.
    """
    options = dict(torch._inductor.list_mode_options(mode)) if mode else {}
    compiled = torch.compile(fn, backend="inductor", fullgraph=fullgraph, dynamic=False, options=options)

    def call(*args, **kwargs):
        with torch._inductor.config.patch(freezing=freezing):
            return compiled(*args, **kwargs)

    return call


def inductor_unavailable() -> str | None:
    """Why inductor cannot compile for the CPU here (no C++ compiler found), or None if it can."""
    try:
        from torch._inductor.cpp_builder import get_cpp_compiler  # lazy: inductor only when compiling

        get_cpp_compiler()
    except Exception as err:  # no C++ compiler, or an inductor without its CPU backend
        return f"inductor cannot compile for the CPU here ({type(err).__name__}: {err})"
    return None


def _weight_versions(model: nn.Module) -> tuple[int, ...]:
    """The version counters of the parameters and buffers (an in-place change increments them)."""
    return tuple(t._version for t in (*model.parameters(), *model.buffers()))


class CompiledStep:
    """:func:`skeleton_mamba.runtime.streaming.step` of ``model`` through :func:`compile_for_inference`.

    ``compiled = CompiledStep(model)`` (or ``model.compile_step()``), then ``y, state = compiled(x,
    state)`` as ``model.step(x, state)``. See the module docstring for compile time, recompiles and
    frozen weights.

    Args:
        model: a causal :class:`~skeleton_mamba.SkeletonMamba` with its final weights, in eval mode.
        freezing: see :func:`compile_for_inference` (False keeps the weights as graph inputs: slower).
        mode: ``torch.compile``'s mode.
    """

    def __init__(self, model: nn.Module, freezing: bool = True, mode: str | None = None) -> None:
        if not model.config.causal:
            raise ValueError(
                "frame-by-frame inference needs a causal backbone: SkeletonMambaConfig(causal=True)"
            )
        self.model = model
        self.signatures: list[tuple] = []  # the input signatures compiled so far

        def frame(x, conv, ssm, context, context_mask):
            return streaming.frame_forward(model, x, conv, ssm, context, context_mask)

        # A code object of its own: dynamo counts versions per code object, so the recompile limit
        # applies to this CompiledStep alone (not to every CompiledStep of the process).
        frame = types.FunctionType(frame.__code__.replace(), frame.__globals__, None, None, frame.__closure__)
        self._frame = compile_for_inference(frame, freezing=freezing, mode=mode)
        self._versions = _weight_versions(model)

    def __call__(
        self,
        x: torch.Tensor,
        state: StreamState,
        context: torch.Tensor | None = None,
        context_mask: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, StreamState]:
        """One frame (B, J, C_in) -> (B, J, D or C_out), ``state`` updated in place (as ``step``)."""
        streaming.check_frame(self.model, x, state, context)
        if _weight_versions(self.model) != self._versions:
            raise RuntimeError("the model's weights changed after its step was compiled: compile it again")
        tensors = (x, context, context_mask, state.conv[0])
        signature = tuple(
            None if t is None else (tuple(t.shape), t.dtype, t.device, t.is_inference()) for t in tensors
        )
        if signature not in self.signatures:
            self.signatures.append(signature)
        try:
            with torch.inference_mode(), torch._dynamo.config.patch(fail_on_recompile_limit_hit=True):
                y = self._frame(x, state.conv, state.ssm, context, context_mask)
        except torch._dynamo.exc.FailOnRecompileLimitHit as err:
            limit = torch._dynamo.config.recompile_limit
            raise RuntimeError(
                f"the compiled frame step reached torch._dynamo.config.recompile_limit ({limit}) versions "
                f"(this one was called with {len(self.signatures)} input signatures: batch size, dtype, "
                "context shape); keep one signature per CompiledStep, or raise the limit"
            ) from err
        state.frames += 1
        return y, state


def compile_step_or_eager(
    model: nn.Module, batch: int = 1, context: torch.Tensor | None = None, **options
) -> tuple[Callable, float | None]:
    """``model``'s step compiled now for ``batch`` streams, or ``model.step`` if compiling fails.

    Compiles by stepping a zero frame through a throwaway state (with ``context``, if the backbone
    reads one), made in the caller's mode: call it under ``torch.inference_mode`` if the frames and the
    state will be inference tensors. ``options`` go to :class:`CompiledStep`. If compiling cannot work here
    (:func:`inductor_unavailable`) or fails (an operator inductor cannot lower, a compiler error), a
    ``RuntimeWarning`` says why and the eager ``model.step`` is returned: the caller runs either way.

    Returns:
        the step function (``model.step``'s signature) and the compile time in seconds (None: eager).
    """
    if (reason := inductor_unavailable()) is not None:
        warnings.warn(f"{reason}; running the frame step eagerly", RuntimeWarning, 2)
        return model.step, None
    weight = next(model.parameters())
    x = weight.new_zeros(batch, model.skeleton.num_joints, model.config.in_channels)
    start = time.perf_counter()
    try:
        compiled = CompiledStep(model, **options)
        compiled(x, model.init_state(batch), context)
    except Exception as err:  # any compiler failure: fall back, never crash
        reason = f"{type(err).__name__}: {str(err).strip().splitlines()[0] if str(err).strip() else ''}"
        warnings.warn(f"compiling the frame step failed ({reason}); running it eagerly", RuntimeWarning, 2)
        return model.step, None
    return compiled, time.perf_counter() - start
