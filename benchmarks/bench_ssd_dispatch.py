"""Is ``ssd``'s choice right? The quadratic and the chunked form timed on the same inputs, per head size.

For each length L and head shape (H heads of width P, state N; one B/C group), the batch holding about
``--tokens`` positions is run forward + backward (gradients for x, dt, B and C) through
:func:`~skeleton_mamba.ssd.quadratic.ssd_quadratic` and :func:`~skeleton_mamba.ssd.chunked.ssd_chunked`
at each ``--chunks`` size, alternately (so a load change hits every form alike), and each row gives the
medians, the fastest form, and what ``impl="torch"`` runs for the mixer's chunk size ``--chunk-size``
(:func:`~skeleton_mamba.ssd.dispatch.choose_impl`) with its time as a ratio to the fastest
(``chosen_over_best``: 1.0 when the dispatch picked the best of the forms it chooses between).

    flock /tmp/bench.lock python benchmarks/bench_ssd_dispatch.py --json
    python benchmarks/bench_ssd_dispatch.py --lengths 150 --shapes 4x8x16 4x64x64 --chunk-size 16
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import alternate_ms, machine_info  # noqa: E402

from skeleton_mamba.ssd.chunked import ssd_chunked  # noqa: E402
from skeleton_mamba.ssd.dispatch import choose_impl  # noqa: E402
from skeleton_mamba.ssd.quadratic import ssd_quadratic  # noqa: E402

SHAPES = ("4x8x16", "4x16x16", "24x8x16", "4x32x32", "4x16x64", "4x64x16", "4x64x64")


def inputs(batch: int, length: int, heads: int, headdim: int, state: int) -> dict[str, torch.Tensor]:
    """Inputs in the regime of an initialised mixer, with gradients for x, dt, B and C."""
    g = torch.Generator().manual_seed(0)
    leaves = dict(
        x=torch.randn(batch, length, heads, headdim, generator=g),
        dt=torch.randn(batch, length, heads, generator=g) - 3.0,
        B=torch.randn(batch, length, 1, state, generator=g),
        C=torch.randn(batch, length, 1, state, generator=g),
    )
    for v in leaves.values():
        v.requires_grad_(True)
    return dict(leaves, A=-torch.linspace(1.0, 16.0, heads), D=torch.ones(heads))


def row(length: int, shape: str, tokens: int, chunks: list[int], chunk_size: int, repeats: int) -> dict:
    heads, headdim, state = (int(v) for v in shape.split("x"))
    batch = max(1, tokens // length)
    inp = inputs(batch, length, heads, headdim, state)

    def run(fn, **kw):
        def go():
            for name in ("x", "dt", "B", "C"):
                inp[name].grad = None
            fn(**inp, **kw).sum().backward()

        return go

    forms = {"quadratic": run(ssd_quadratic)}
    forms.update({f"chunked_{q}": run(ssd_chunked, chunk_size=q) for q in chunks if q < length})
    if f"chunked_{chunk_size}" not in forms and chunk_size < length:
        forms[f"chunked_{chunk_size}"] = run(ssd_chunked, chunk_size=chunk_size)
    ms = {name: round(v, 2) for name, v in alternate_ms(forms, repeats).items()}
    chosen = choose_impl(inp["x"], chunk_size, stateful=False, impl="torch", state_size=state)
    chosen_key = "quadratic" if chosen == "quadratic" else f"chunked_{chunk_size}"
    rivals = {k: v for k, v in ms.items() if k in ("quadratic", f"chunked_{chunk_size}")}
    return {
        "length": length,
        "heads": heads,
        "headdim": headdim,
        "state": state,
        "batch": batch,
        "ms": ms,
        "fastest": min(ms, key=ms.get),
        "chosen": chosen_key,
        "chosen_over_best": round(ms[chosen_key] / min(rivals.values()), 2),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lengths", type=int, nargs="+", default=[64, 150, 256])
    ap.add_argument("--shapes", nargs="+", default=list(SHAPES), help="HEADSxHEADDIMxSTATE")
    ap.add_argument("--chunks", type=int, nargs="+", default=[16, 32, 64], help="chunked form's sizes")
    ap.add_argument("--chunk-size", type=int, default=16, help="the mixer's chunk_size given to the dispatch")
    ap.add_argument("--tokens", type=int, default=96 * 150, help="positions per call (batch x length)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    rows = []
    for length in args.lengths:
        for shape in args.shapes:
            r = row(length, shape, args.tokens, args.chunks, args.chunk_size, args.repeats)
            rows.append(r)
            if not args.json:
                print(r, flush=True)
    if args.json:
        result = {"machine": machine_info(), "threads": args.threads, "chunk_size": args.chunk_size}
        print(json.dumps(dict(result, rows=rows), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
