"""``--recipe NAME|PATH``: resolve a recipe name to the packaged YAML file.

jsonargparse allows one config action per parser, so ``--recipe`` is an alias of LightningCLI's
``-c/--config`` (same destination): :class:`RecipeConfigAction` resolves its value and hands the
resolved path to :class:`jsonargparse.ActionConfigFile`. Resolution order for a value:

1. an existing file on disk is used as is (``--recipe my_recipe.yaml``);
2. a YAML mapping given inline (``--config '{trainer: {max_epochs: 1}}'``) is passed through;
3. otherwise the value is looked up among the packaged recipes
   (``importlib.resources.files("skeleton_mamba.recipes")``), with or without the ``.yaml`` suffix;
4. an unknown name ends in ``parser.error`` listing the available recipes; a file that is not valid
   YAML ends in ``parser.error`` naming the file, line and column.

Several ``--recipe``/``--config`` options and dotted overrides merge left to right.

A recipe may be an *overlay* of another: a top-level ``base: ntu60.yaml`` (a path relative to the overlay's
folder, or a packaged name; a list merges several) is applied first, then the overlay's own keys, exactly as
``--recipe ntu60.yaml --config overlay.yaml`` would (a list, such as the loggers, is replaced as a whole).
"""

from __future__ import annotations

import importlib.resources
import os
from pathlib import Path

import yaml
from jsonargparse import ActionConfigFile

RECIPE_PACKAGE = "skeleton_mamba.recipes"
RECIPE_SUFFIXES = (".yaml", ".yml")
BASE_KEY = "base"  # an overlay's base recipe(s)

__all__ = [
    "RecipeConfigAction",
    "packaged_recipe_dir",
    "packaged_recipes",
    "recipe_description",
    "resolve_recipe",
]


def packaged_recipe_dir() -> Path:
    """The folder of the packaged recipes (a real directory: editable, wheel and sdist installs)."""
    root = importlib.resources.files(RECIPE_PACKAGE)
    path = Path(str(root))
    if not path.is_dir():
        raise RuntimeError(f"the packaged recipes are not on the file system ({root}); install unzipped")
    return path


def packaged_recipes() -> dict[str, Path]:
    """Recipe file name -> path, for the top-level ``*.yaml`` files of the recipe package.

    Sub-folders (``backbones/``) hold fragments that recipes include; they are not recipes.
    """
    folder = packaged_recipe_dir()
    return {p.name: p for p in sorted(folder.iterdir()) if p.is_file() and p.suffix in RECIPE_SUFFIXES}


def recipe_description(path: Path) -> str:
    """The recipe's one-line description: its first ``# `` comment line (empty when there is none)."""
    with open(path, encoding="utf-8") as f:
        for line in f:
            stripped = line.strip()
            if not stripped:
                continue
            if stripped.startswith("#"):
                return stripped.lstrip("#").strip()
            return ""
    return ""


def resolve_recipe(value: str) -> Path | None:
    """The file a ``--recipe`` value names: an existing path, else a packaged recipe; ``None`` if neither."""
    candidate = Path(value).expanduser()
    if candidate.is_file():
        return candidate
    recipes = packaged_recipes()
    for name in (value, *(value + s for s in RECIPE_SUFFIXES)):
        if name in recipes:
            return recipes[name]
    return None


def _is_inline_mapping(value: str) -> bool:
    try:
        return isinstance(yaml.safe_load(value), dict)
    except yaml.YAMLError:
        return False


class RecipeConfigAction(ActionConfigFile):
    """``-c/--config/--recipe``: a config file, an inline YAML mapping or a packaged recipe name."""

    def __call__(self, parser, cfg, values, option_string=None):
        if not _is_inline_mapping(values):
            resolved = resolve_recipe(values)
            if resolved is None:
                available = ", ".join(packaged_recipes()) or "(none installed)"
                parser.error(
                    f"{option_string or '--recipe'} {values!r}: no such file and no packaged recipe of that "
                    f"name. Available recipes: {available} (`sm recipes` describes them)."
                )
            _check_yaml(parser, resolved)
            self._apply_recipe(parser, cfg, resolved, option_string, ())
            return
        super().__call__(parser, cfg, values, option_string)

    def _apply_recipe(self, parser, cfg, path: Path, option_string, overlays: tuple[Path, ...]) -> None:
        """Apply the recipe at ``path``: its ``base`` recipes first (recursively), then its own keys."""
        content = yaml.safe_load(path.read_text(encoding="utf-8"))
        if not isinstance(content, dict) or BASE_KEY not in content:
            super().__call__(parser, cfg, str(path), option_string)
            return
        if path.resolve() in overlays:
            parser.error(f"{path}: its base recipes include itself")
        bases = content.pop(BASE_KEY)
        for name in [bases] if isinstance(bases, str) else bases:
            base = path.parent / str(name)
            base = base if base.is_file() else resolve_recipe(str(name))
            if base is None:
                parser.error(f"{path}: base recipe {name!r}: no such file next to it and no packaged recipe")
            _check_yaml(parser, base)
            self._apply_recipe(parser, cfg, base, option_string, (*overlays, path.resolve()))
        cwd = os.getcwd()
        os.chdir(path.parent)  # relative paths in the overlay (a backbone fragment) resolve as in its file
        try:
            super().__call__(parser, cfg, yaml.safe_dump(content), option_string)
        finally:
            os.chdir(cwd)


def _check_yaml(parser, path: Path) -> None:
    """``parser.error`` naming ``path`` and the line of a YAML syntax error (jsonargparse names neither)."""
    try:
        yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark is not None else str(path)
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        parser.error(f"{where}: YAML syntax error in the recipe: {problem}")
    except (OSError, UnicodeDecodeError) as err:
        parser.error(f"{path}: cannot read the recipe ({err})")
