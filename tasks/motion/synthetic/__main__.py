"""``python -m skeleton_mamba.tasks.motion.synthetic --out DIR``: write a synthetic dance + music demo set."""

from __future__ import annotations

import argparse
import sys

from skeleton_mamba.tasks.motion.io.option_types import int_option, real_option, seed_option
from skeleton_mamba.tasks.motion.synthetic import make_demo_set


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m skeleton_mamba.tasks.motion.synthetic", description=__doc__)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument(
        "--count", type=int_option(1, 1_000_000, "a count"), default=4, help="number of dance + music pairs"
    )
    p.add_argument(
        "--duration",
        type=real_option(0.0, 86_400.0, "seconds", low_open=True),
        default=20.0,
        help="seconds per pair",
    )
    p.add_argument("--seed", type=seed_option, default=0, help="random seed")
    args = p.parse_args(argv)
    for motion, music in make_demo_set(args.out, args.count, args.duration, args.seed):
        print(f"{motion}  {music}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
