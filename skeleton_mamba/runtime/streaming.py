"""Frame-by-frame inference of a causal SkeletonMamba in constant memory.

A causal backbone (``SkeletonMambaConfig(causal=True)``: forward-only Temporal Scan) is a recurrence
over frames. Within a block, only the Temporal Scan mixes time; everything else is frame-local:

- the Human Tokenizer, Group Scan and Joint Scan scan the tokens of one frame (groups, joints),
  so for frame t they are the frame-wise computation on frame t alone;
- the LayerNorms, the MLP and the joint embedding act per token;
- the cross-attention lets every joint token attend over the condition sequence ``context``
  (B, S, Dc), with no time axis of its own. In a stream, ``context`` is whatever the caller passes
  for that frame; it equals the batch forward when every step receives the same ``context`` as
  the batch call (a stream-level condition: a style, genre or text token). A condition that is
  aligned with the frames (music) must not go through cross-attention in a causal model, as
  every frame would attend to the whole sequence, future included: feed it as per-frame input
  features instead (as ``tasks/stream``'s dance model does).

The Temporal Scan's forward mixer carries, per block and per joint sequence, the two states of
:meth:`Mamba2Mixer.step <skeleton_mamba.mixer.Mamba2Mixer.step>` (from its ``allocate_inference_cache``,
the layout of ``mamba_ssm.Mamba2``'s): the last ``d_conv`` inputs of its depthwise convolution,
``conv (B*J, conv_dim, d_conv)``, and the SSD state ``ssm (B*J, nheads, headdim, d_state)``, updated
in place:

    h_t = exp(Δ_t A) h_{t-1} + (Δ_t x_t) ⊗ B_t,   y_t = h_t C_t + D ⊙ x_t     ([Mamba-2] SSD recurrence)

Nothing else is kept, so the state's size is fixed whatever the number of frames seen.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from skeleton_mamba.runtime.frame_ops import FrameOps


@dataclass
class StreamState:
    """Recurrent state of a causal SkeletonMamba for a batch of ``batch`` streams.

    Attributes:
        batch: number of streams B.
        conv: per block, the Temporal Scan's convolution window (B*J, conv_dim, d_conv).
        ssm: per block, the Temporal Scan's SSD state (B*J, nheads, headdim, d_state), in the
            SSD's compute dtype (fp32, fp64 for fp64 models).
        frames: frames consumed so far (a counter; not part of the recurrence).
    """

    batch: int
    conv: list[torch.Tensor]
    ssm: list[torch.Tensor]
    frames: int = 0

    @property
    def nbytes(self) -> int:
        """Bytes held by the state tensors (independent of ``frames``)."""
        return sum(t.numel() * t.element_size() for t in (*self.conv, *self.ssm))

    def reset(self) -> None:
        """Start a new stream (zero state), in place."""
        for t in (*self.conv, *self.ssm):
            t.zero_()
        self.frames = 0


def init_state(model, batch: int, dtype: torch.dtype | None = None, device=None) -> StreamState:
    """The zero state of ``model`` (a causal :class:`SkeletonMamba`) for ``batch`` streams."""
    if not model.config.causal:
        raise ValueError("frame-by-frame inference needs a causal backbone: SkeletonMambaConfig(causal=True)")
    rows = batch * model.skeleton.num_joints
    mixers = [block.temporal_scan.forward_mixer for block in model.blocks]
    states = [mixer.allocate_inference_cache(rows, dtype=dtype, device=device) for mixer in mixers]
    return StreamState(batch, [c for c, _ in states], [s for _, s in states])


def block_step(
    block,
    x: torch.Tensor,
    conv_state: torch.Tensor,
    ssm_state: torch.Tensor,
    context: torch.Tensor | None = None,
    context_mask: torch.Tensor | None = None,
    ops=FrameOps,
) -> torch.Tensor:
    """One frame through a causal :class:`SkeletonMambaBlock`: x (B, J, D) -> (B, J, D).

    ``ops``: the operations of the frame-wise scans (:class:`FrameOps`; ``None``: the modules' own
    sequence path, as in the batch forward; same result, more operations).
    """
    if block.cross_attention is not None and context is None:
        raise ValueError("this backbone was built with context_dim: pass a context (B, S, Dc)")
    b, j, d = x.shape
    x = block.spatial(x[:, None], ops)  # (B, 1, J, D): Group Scan and Joint Scan of this frame
    scan = block.temporal_scan
    seq = block.norm_time(x).reshape(b * j, d)
    x = x + scan.proj(scan.forward_mixer.step(seq, conv_state, ssm_state)).view(b, 1, j, d)
    return block.pointwise(x, context, context_mask)[:, 0]


def check_frame(model, x: torch.Tensor, state: StreamState, context: torch.Tensor | None = None) -> None:
    """Raise a ValueError unless ``x`` is one frame (B, J, C) of ``state``'s streams of ``model``, with a
    ``context`` when the backbone was built with cross-attention."""
    j = model.skeleton.num_joints
    if x.dim() != 3 or x.shape[0] != state.batch or x.shape[1] != j:
        raise ValueError(
            f"expected one frame (B={state.batch}, {j}, C) for skeleton {model.skeleton.name}, "
            f"got {tuple(x.shape)}"
        )
    if context is None and any(block.cross_attention is not None for block in model.blocks):
        raise ValueError("this backbone was built with context_dim: pass a context (B, S, Dc)")


def frame_forward(
    model,
    x: torch.Tensor,
    conv: list[torch.Tensor],
    ssm: list[torch.Tensor],
    context: torch.Tensor | None = None,
    context_mask: torch.Tensor | None = None,
    ops=FrameOps,
) -> torch.Tensor:
    """The computation of :func:`step` (no checks, no counter): x (B, J, C_in) -> (B, J, D or C_out).

    ``conv`` and ``ssm`` (the :class:`StreamState` lists, one tensor per block) are updated in place.
    This is the function :class:`~skeleton_mamba.runtime.compiling.CompiledStep` compiles.
    """
    h = model.input_proj(x)
    if model.joint_embedding is not None:
        h = h + model.joint_embedding
    for block, conv_state, ssm_state in zip(model.blocks, conv, ssm):
        h = block_step(block, h, conv_state, ssm_state, context, context_mask, ops)
    return model.output_proj(model.norm(h))


def step(
    model,
    x: torch.Tensor,
    state: StreamState,
    context: torch.Tensor | None = None,
    context_mask: torch.Tensor | None = None,
    ops=FrameOps,
) -> tuple[torch.Tensor, StreamState]:
    """One frame through a causal :class:`SkeletonMamba` (inference only: no autograd).

    Args:
        x: (B, J, C_in) the new frame of every stream.
        state: from :func:`init_state`; updated in place and returned.
        context: (B, S, Dc) the condition for this frame (see the module docstring).
        context_mask: (B, S) bool, True on valid condition tokens.
        ops (type[FrameOps]): the frame-wise scans' operations (see :func:`block_step`).

    Returns:
        (B, J, D or C_out) the output for this frame, and ``state``.
    """
    check_frame(model, x, state, context)
    with torch.inference_mode():
        y = frame_forward(model, x, state.conv, state.ssm, context, context_mask, ops)
    state.frames += 1
    return y, state


__all__ = [
    "StreamState",
    "block_step",
    "check_frame",
    "frame_forward",
    "init_state",
    "step",
]
