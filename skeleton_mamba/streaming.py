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
``mamba_ssm.Mamba2.step`` (layout of ``Mamba2.allocate_inference_cache``): the last ``d_conv``
inputs of its depthwise convolution, ``conv (B*J, conv_dim, d_conv)``, and the SSD state
``ssm (B*J, nheads, headdim, d_state)``, updated in place:

    h_t = exp(Δ_t A) h_{t-1} + (Δ_t x_t) ⊗ B_t,   y_t = h_t C_t + D ⊙ x_t     ([Mamba-2] SSD recurrence)

Nothing else is kept, so the state's size is fixed whatever the number of frames seen.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from skeleton_mamba.frame_ops import FrameOps
from skeleton_mamba.mixer import Mamba2Mixer
from skeleton_mamba.ssd.discretize import compute_dtype, discretize_dt


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


def allocate_mixer_state(
    mixer: Mamba2Mixer, batch: int, dtype: torch.dtype | None = None, device: torch.device | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Zero ``(conv (batch, conv_dim, d_conv), ssm (batch, nheads, headdim, d_state))`` for ``mixer``.

    ``dtype`` defaults to the mixer's weights; the SSD state is kept in the SSD's compute dtype.
    """
    weight = mixer.conv1d.weight
    dtype = dtype or weight.dtype
    device = device or weight.device
    conv_dim, d_conv = weight.shape[0], weight.shape[-1]
    conv = torch.zeros(batch, conv_dim, d_conv, dtype=dtype, device=device)
    ssm_dtype = compute_dtype(torch.empty(0, dtype=dtype))
    ssm = torch.zeros(batch, mixer.nheads, mixer.headdim, mixer.d_state, dtype=ssm_dtype, device=device)
    return conv, ssm


def mixer_step(
    mixer: Mamba2Mixer, u: torch.Tensor, conv_state: torch.Tensor, ssm_state: torch.Tensor
) -> torch.Tensor:
    """One token through ``mixer``: u (B, d_model) -> (B, d_model); both states updated in place.

    Equal to the last output of ``mixer(cat(previous tokens, u))`` (as ``mamba_ssm.Mamba2.step``).
    """
    b = u.shape[0]
    h, p, n, g = mixer.nheads, mixer.headdim, mixer.d_state, mixer.ngroups
    zxbcdt = mixer.in_proj(u)
    z0, x0, z, xbc, dt = torch.split(
        zxbcdt, [mixer.d_mlp, mixer.d_mlp, mixer.d_ssm, mixer.d_ssm + 2 * g * n, h], dim=-1
    )

    # Causal depthwise convolution over the last d_conv inputs (shift the window left, append).
    window = torch.cat([conv_state[..., 1:], xbc[..., None]], dim=-1)
    conv_state.copy_(window)
    xbc = (window * mixer.conv1d.weight[:, 0]).sum(-1)  # (B, conv_dim)
    if mixer.conv1d.bias is not None:
        xbc = xbc + mixer.conv1d.bias
    x, B, C = torch.split(F.silu(xbc), [mixer.d_ssm, g * n, g * n], dim=-1)

    ct = ssm_state.dtype
    # Δ as the sequence forward (with dt_limit; mamba_ssm's own step skips the limit), (B, H)
    delta = discretize_dt(dt, mixer.dt_bias, True, mixer.dt_limit, ct)
    xh = x.to(ct).view(b, h, p)
    decay = torch.exp(delta * -torch.exp(mixer.A_log.to(ct)))  # exp(Δ A), (B, H)
    xd = xh * delta[:, :, None]  # Δ x, (B, H, P)
    if torch.compiler.is_compiling():
        y = _state_update_pointwise(ssm_state, decay, xd, B.to(ct), C.to(ct), g)
    else:
        ssm_state.mul_(decay[:, :, None, None])
        # Heads g*R .. g*R + R - 1 read B/C group g: one product per (stream, group), (B*G, R*P, N).
        state = ssm_state.view(b * g, (h // g) * p, n)
        state.baddbmm_(xd.view(b * g, -1, 1), B.to(ct).reshape(b * g, 1, n))  # += (Δx) ⊗ B
        y = torch.bmm(state, C.to(ct).reshape(b * g, n, 1)).view(b, h, p)
    D = mixer.skip_weight().to(ct)  # (H,) or (H, P)
    y = torch.addcmul(y, xh, D[:, None] if D.dim() == 1 else D)
    y = mixer.gate(y.to(u.dtype).view(b, mixer.d_ssm), z)
    if mixer.d_mlp:
        y = torch.cat([F.silu(z0) * x0, y], dim=-1)
    return mixer.out_proj(y)


def _state_update_pointwise(
    ssm_state: torch.Tensor, decay: torch.Tensor, xd: torch.Tensor, B: torch.Tensor, C: torch.Tensor, g: int
) -> torch.Tensor:
    """h <- exp(Δ A) h + (Δ x) ⊗ B in place, and y = h C, as element-wise work and a reduction.

    The form for compiled code (:class:`~skeleton_mamba.compiling.CompiledStep`): inductor computes the
    new state directly into ``ssm_state``'s storage (no matrix product whose result is copied back).
    ssm_state (B, H, P, N), decay (B, H), xd (B, H, P), B and C (B, G*N) -> y (B, H, P).
    """
    b, h, p, n = ssm_state.shape
    r = h // g
    new = (ssm_state * decay[:, :, None, None]).view(b, g, r, p, n)
    new = new + xd.view(b, g, r, p, 1) * B.view(b, g, 1, 1, n)
    ssm_state.copy_(new.view(b, h, p, n))
    return (new * C.view(b, g, 1, 1, n)).sum(-1).view(b, h, p)


def init_state(model, batch: int, dtype: torch.dtype | None = None, device=None) -> StreamState:
    """The zero state of ``model`` (a causal :class:`SkeletonMamba`) for ``batch`` streams."""
    if not model.config.causal:
        raise ValueError("frame-by-frame inference needs a causal backbone: SkeletonMambaConfig(causal=True)")
    rows = batch * model.skeleton.num_joints
    mixers = [block.temporal_scan.forward_mixer for block in model.blocks]
    states = [allocate_mixer_state(mixer, rows, dtype, device) for mixer in mixers]
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
    x = x + scan.proj(mixer_step(scan.forward_mixer, seq, conv_state, ssm_state)).view(b, 1, j, d)
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
    This is the function :class:`~skeleton_mamba.compiling.CompiledStep` compiles.
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
        ops: the frame-wise scans' operations (see :func:`block_step`).

    Returns:
        (B, J, D or C_out) the output for this frame, and ``state``.
    """
    check_frame(model, x, state, context)
    with torch.inference_mode():
        y = frame_forward(model, x, state.conv, state.ssm, context, context_mask, ops)
    state.frames += 1
    return y, state


# glibc mallopt parameters (malloc.h) and the values keep_freed_memory sets.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 32 << 20  # the largest glibc accepts on 64-bit
TRIM_THRESHOLD = 1 << 30


def keep_freed_memory() -> bool:
    """Let glibc keep freed memory for reuse instead of returning it to the kernel (process-wide).

    A step allocates and frees the same few hundred kB buffers every frame. With glibc's adaptive
    defaults, blocks above the mmap threshold are fresh mappings and the top of the heap is trimmed
    when enough is free, so a frame could start with thousands of minor page faults (measured: about
    4,000 per paper-width frame, 16 MB of zero-filled pages) depending on the order of allocations.
    Fixed thresholds (mmap above 32 MiB, trim above 1 GiB) keep the blocks in the heap: 0 faults per
    frame, and the resident memory stays at its high-water mark (flat). Returns False (nothing done)
    where the C library has no ``mallopt`` (not glibc).
    """
    path = ctypes.util.find_library("c")
    try:
        mallopt = ctypes.CDLL(path).mallopt
    except (OSError, AttributeError, TypeError):
        return False
    mmap_set = bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD))
    return mmap_set and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))


__all__ = [
    "StreamState",
    "allocate_mixer_state",
    "block_step",
    "check_frame",
    "frame_forward",
    "init_state",
    "keep_freed_memory",
    "mixer_step",
    "step",
]
