"""``sm recipes``: the packaged recipes, each with the description from its leading ``# `` line."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from skeleton_mamba.tasks.training.recipe_resolution import packaged_recipes, recipe_description
from skeleton_mamba.tasks.training.recipes_args import build_parser

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Print ``NAME  DESCRIPTION`` per recipe; 1 when none is installed."""
    build_parser().parse_args(list(argv or []))
    recipes = packaged_recipes()
    width = max((len(name) for name in recipes), default=0)
    for name, path in recipes.items():
        print(f"{name:<{width}}  {recipe_description(path)}")
    if not recipes:
        print("no packaged recipes found", file=sys.stderr)
        return 1
    return 0
