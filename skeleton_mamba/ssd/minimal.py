"""The SSD on one page: what every SSD form of this package computes ([Mamba-2] Sec. 6, Listing 1).

Read this file first; the other modules of :mod:`skeleton_mamba.ssd` compute the same numbers faster, with
any length, the skip D, Δ's discretisation, fp32 accuracy and gradients, and each is tested against
:func:`ssd_minimal`.

The discretised inputs are ``X = Δ x`` (b, L, H, P), the log decays ``a = Δ A`` (b, L, H), never positive, and
the projections ``B``, ``C`` (b, L, G, N), head h reading group h // (H / G). The state-space recurrence

    h_t = exp(a_t) h_{t-1} + X_t ⊗ B_t,        y_t = h_t C_t

unrolls to ``y = M X`` with the 1-semiseparable matrix ``M[t, s] = exp(a_{s+1} + ... + a_t) (C_t · B_s)``
for s <= t (0 above the diagonal): attention with a causal decay mask. Cut the length into chunks of Q frames
and M into Q x Q blocks; the block decomposition computes y in four steps:

1. **diagonal blocks** (output from inside the chunk): the quadratic form on each chunk;
2. **chunk states** (right factors of the off-diagonal blocks): each chunk's final state from a zero state;
3. **state passing** (middle factors): a recurrence over the chunks, the state entering chunk k+1 is the
   one entering chunk k decayed through it plus chunk k's own;
4. **state to output** (left factors): each chunk reads its entering state, decayed to each frame, with C.

y is the sum of steps 1 and 4. Steps 1, 2 and 4 are matrix products (tensor cores on a GPU); step 3 is the
only sequential part, one step per chunk instead of one per frame.
"""

from __future__ import annotations

import torch
from einops import rearrange, repeat

__all__ = ["segsum", "ssd_minimal"]


def segsum(a: torch.Tensor) -> torch.Tensor:
    """Segment sums (..., Q) -> (..., Q, Q): entry [i, j] = a_{j+1} + ... + a_i for i >= j, -inf above the
    diagonal, so ``exp(segsum(a))`` is the causal decay mask of one chunk. Each entry adds only its own
    terms (no difference of two long cumulative sums, which would lose the small ones).

    Examples:
        >>> segsum(torch.tensor([1.0, 2.0, 3.0]))
        tensor([[0., -inf, -inf],
                [2., 0., -inf],
                [5., 3., 0.]])
    """
    q = a.shape[-1]
    below = torch.ones(q, q, dtype=torch.bool, device=a.device).tril(-1)
    terms = repeat(a, "... i -> ... i j", j=q).masked_fill(~below, 0.0)  # [i, j] = a_i where i > j
    sums = terms.cumsum(dim=-2)  # [i, j] = a_{j+1} + ... + a_i
    causal = torch.ones(q, q, dtype=torch.bool, device=a.device).tril()
    return sums.masked_fill(~causal, -torch.inf)


def ssd_minimal(
    X: torch.Tensor,
    a: torch.Tensor,
    B: torch.Tensor,
    C: torch.Tensor,
    chunk_size: int,
    initial_state: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The SSD by the four steps of the block decomposition (module docstring).

    Args:
        X: (b, L, H, P) the discretised inputs Δ x.
        a: (b, L, H) the log decays Δ A (<= 0).
        B: (b, L, G, N) input projections (G divides H).
        C: (b, L, G, N) output projections.
        chunk_size: Q; L must be a multiple of it.
        initial_state: (b, H, P, N) the state before the first frame, or None (zeros).

    Returns:
        y (b, L, H, P) and the final state (b, H, P, N).

    Examples:
        >>> X, a = torch.ones(1, 4, 1, 1), torch.zeros(1, 4, 1)  # no decay: y_t sums X_s (C_t . B_s)
        >>> B = C = torch.ones(1, 4, 1, 1)
        >>> y, state = ssd_minimal(X, a, B, C, chunk_size=2)
        >>> y.flatten().tolist(), state.item()
        ([1.0, 2.0, 3.0, 4.0], 4.0)
    """
    length, heads = X.shape[1], X.shape[2]
    if length % chunk_size:
        raise ValueError(f"ssd_minimal: the length {length} is not a multiple of chunk_size {chunk_size}")
    groups = B.shape[2]
    B = repeat(B, "b l g n -> b l (g r) n", r=heads // groups)  # head h reads group h // (H / G)
    C = repeat(C, "b l g n -> b l (g r) n", r=heads // groups)
    X, B, C = (rearrange(t, "b (c q) h z -> b c q h z", q=chunk_size) for t in (X, B, C))
    a = rearrange(a, "b (c q) h -> b h c q", q=chunk_size)
    a_cumsum = a.cumsum(dim=-1)  # (b, h, c, q): the log decay from the chunk's start to each frame

    # 1. Diagonal blocks: y_t = sum over s <= t in the chunk of exp(a_{s+1} + ... + a_t) (C_t . B_s) X_s.
    decay = torch.exp(segsum(a))  # (b, h, c, q_t, q_s)
    y_diag = torch.einsum("bcthn,bcshn,bhcts,bcshp->bcthp", C, B, decay, X)

    # 2. Chunk states: each chunk's final state from zero, every input decayed to the chunk's end.
    to_end = torch.exp(a_cumsum[..., -1:] - a_cumsum)  # (b, h, c, q)
    states = torch.einsum("bcshn,bhcs,bcshp->bchpn", B, to_end, X)

    # 3. State passing: S_{k+1} = exp(total decay of chunk k) S_k + states_k, from the initial state S_0.
    if initial_state is None:
        initial_state = torch.zeros_like(states[:, :1])
    else:
        initial_state = initial_state[:, None]
    states = torch.cat([initial_state, states], dim=1)  # (b, c + 1, h, p, n)
    chunk_decay = torch.exp(segsum(torch.nn.functional.pad(a_cumsum[..., -1], (1, 0))))  # (b, h, c+1, c+1)
    entering = torch.einsum("bhzc,bchpn->bzhpn", chunk_decay, states)
    states, final_state = entering[:, :-1], entering[:, -1]  # entering chunk k; after the last chunk

    # 4. State to output: chunk k reads its entering state decayed to each frame, through C.
    from_start = torch.exp(a_cumsum)  # (b, h, c, q)
    y_off = torch.einsum("bclhn,bchpn,bhcl->bclhp", C, states, from_start)

    y = rearrange(y_diag + y_off, "b c q h p -> b (c q) h p")
    return y, final_state
