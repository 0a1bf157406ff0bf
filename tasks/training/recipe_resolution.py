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

import jsonargparse
import yaml
from jsonargparse import ActionConfigFile

from skeleton_mamba.errors import InputError
from skeleton_mamba.io.bounded_read import read_text

RECIPE_PACKAGE = "skeleton_mamba.recipes"
RECIPE_SUFFIXES = (".yaml", ".yml")
BASE_KEY = "base"  # an overlay's base recipe(s)

# Bounds of every recipe, ``--config`` file and YAML-valued option: the packaged recipes are a few KiB with
# a few hundred nodes nested < 10 deep, so these leave room for any real recipe and refuse alias / merge-key
# bombs ("billion laughs") and deep nesting before anything is expanded or recursed into.
MAX_RECIPE_BYTES = 1 << 20  # a recipe file or inline YAML value, in bytes
MAX_RECIPE_NODES = 100_000  # scalars + sequences + mappings once every alias is expanded
MAX_RECIPE_DEPTH = 64  # nested sequences / mappings

__all__ = [
    "MAX_RECIPE_BYTES",
    "MAX_RECIPE_DEPTH",
    "MAX_RECIPE_NODES",
    "RecipeConfigAction",
    "bounded_yaml_load",
    "check_yaml_bounds",
    "install_bounded_yaml_loader",
    "read_recipe_text",
    "read_yaml_file",
    "packaged_recipe_dir",
    "packaged_recipes",
    "recipe_description",
    "resolve_backbone",
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
    if candidate.is_file() or (candidate.exists() and not candidate.is_dir()):
        return candidate  # a FIFO or a device too: the bounded reader refuses it, naming what it is
    recipes = packaged_recipes()
    for name in (value, *(value + s for s in RECIPE_SUFFIXES)):
        if name in recipes:
            return recipes[name]
    return None


def resolve_backbone(value: str) -> Path | None:
    """The file a backbone value names (``sm export-onnx --backbone``): an existing path, else a packaged
    fragment as a recipe names it (``backbones/skeleton_mamba_tiny.yaml``) or by its name alone
    (``skeleton_mamba_tiny``, with or without ``.yaml``); ``None`` if neither."""
    candidate = Path(value).expanduser()
    if candidate.is_file():
        return candidate
    parts = Path(value).parts
    if parts[:1] == ("backbones",):
        parts = parts[1:]
    if len(parts) != 1:
        return None
    folder = packaged_recipe_dir() / "backbones"
    for name in (parts[0], *(parts[0] + s for s in RECIPE_SUFFIXES)):
        if (folder / name).is_file() and (folder / name).suffix in RECIPE_SUFFIXES:
            return folder / name
    return None


def check_yaml_bounds(text: str, source: str = "YAML value") -> None:
    """Raise :class:`InputError` naming ``source`` (and the line) if ``text`` passes the recipe bounds.

    Size first; then depth, with PyYAML's event parser (a state machine: no recursion, nothing built);
    then the node graph is composed (aliases are shared nodes there, so a bomb is still small) and its
    size once expanded counted with one memoised sum per node, the size ``yaml.safe_dump`` or jsonargparse
    would build. Syntax errors are left to the caller's parser, which names their line.
    """
    if len(text) > MAX_RECIPE_BYTES:
        raise InputError(f"{source}: {len(text):,} bytes, more than a recipe's {MAX_RECIPE_BYTES:,}")
    depth = 0
    try:
        for event in yaml.parse(text, Loader=yaml.SafeLoader):
            if isinstance(event, yaml.CollectionStartEvent):
                depth += 1
                if depth > MAX_RECIPE_DEPTH:
                    line = event.start_mark.line + 1
                    raise InputError(f"{source}:{line}: nested more than {MAX_RECIPE_DEPTH} levels deep")
            elif isinstance(event, yaml.CollectionEndEvent):
                depth -= 1
        nodes = list(yaml.compose_all(text, Loader=yaml.SafeLoader))
    except yaml.YAMLError:
        return
    sizes: dict[int, int] = {}
    stack = [(node, False) for node in nodes if node is not None]
    while stack:  # post-order without recursion: a node's size is 1 + its children's (expanded) sizes
        node, children_done = stack.pop()
        if id(node) in sizes:
            continue
        children = (
            node.value
            if isinstance(node, yaml.SequenceNode)
            else [n for pair in node.value for n in pair]
            if isinstance(node, yaml.MappingNode)
            else []
        )
        if children_done:
            sizes[id(node)] = 1 + sum(sizes.get(id(c), 0) for c in children)
            if sizes[id(node)] > MAX_RECIPE_NODES:
                line = node.start_mark.line + 1
                raise InputError(
                    f"{source}:{line}: more than {MAX_RECIPE_NODES:,} values once its aliases are expanded "
                    "(an alias or merge-key bomb?)"
                )
            continue
        stack.append((node, True))
        stack.extend((c, False) for c in children if id(c) not in sizes)


def read_recipe_text(path: str | os.PathLike[str], what: str = "recipe") -> str:
    """The text of a YAML file (a recipe, a backbone file) through the project's bounded reader: a regular
    file of at most :data:`MAX_RECIPE_BYTES`, UTF-8 (:mod:`skeleton_mamba.io.bounded_read`)."""
    return read_text(path, max_bytes=MAX_RECIPE_BYTES, what=what, error=InputError)


def read_yaml_file(path: str | os.PathLike[str], what: str = "recipe"):
    """A YAML file read by :func:`read_recipe_text` and loaded within the recipe bounds; a syntax error is
    one :class:`InputError` naming the file, line and column."""
    text = read_recipe_text(path, what)
    try:
        return bounded_yaml_load(text, str(path))
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark is not None else str(path)
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise InputError(f"{where}: YAML syntax error in the {what}: {problem}") from None


def bounded_yaml_load(text: str, source: str = "YAML value"):
    """``yaml.safe_load`` within :func:`check_yaml_bounds`."""
    check_yaml_bounds(text, source)
    return yaml.safe_load(text)


class _BoundedLoader:
    """jsonargparse's YAML loader (every ``--config`` file, inline mapping and option value) within bounds."""

    def __init__(self, inner) -> None:
        self.inner = inner

    def __call__(self, stream: str):
        if isinstance(stream, str):
            check_yaml_bounds(stream, "--config/option YAML value")
        return self.inner(stream)


def install_bounded_yaml_loader() -> None:
    """Route jsonargparse's ``yaml`` parser mode through :func:`check_yaml_bounds` (idempotent).

    The loader wrapped is jsonargparse's own (public ``get_loader``), so its handling of plain option values
    (``--x a`` stays the string ``a``) is unchanged.
    """
    current = jsonargparse.get_loader("yaml")
    if not isinstance(current, _BoundedLoader):
        jsonargparse.set_loader("yaml", _BoundedLoader(current), exceptions=(yaml.YAMLError,))


def _is_inline_mapping(value: str) -> bool:
    try:
        return isinstance(bounded_yaml_load(value, "--config inline YAML"), dict)
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
        content = bounded_yaml_load(read_recipe_text(path), str(path))
        if content is not None and not isinstance(content, dict):
            parser.error(
                f"{path}: not a recipe (a YAML mapping of `key: value` lines is expected, the file holds a "
                f"{type(content).__name__})"
            )
        if content is None or BASE_KEY not in content:
            self._apply_named(parser, cfg, str(path), option_string, str(path))
            return
        if path.resolve() in overlays:
            parser.error(f"{path}: its base recipes include itself")
        bases = content.pop(BASE_KEY)
        if not (
            isinstance(bases, str) or (isinstance(bases, list) and all(isinstance(b, str) for b in bases))
        ):
            parser.error(
                f"{path}: `{BASE_KEY}` names a recipe or a list of recipes, got {type(bases).__name__}"
            )
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
            self._apply_named(parser, cfg, yaml.safe_dump(content), option_string, str(path))
        finally:
            os.chdir(cwd)
        applied = cfg.get(self.dest)
        if isinstance(applied, list) and applied and applied[-1] is None:  # applied as text: name its file
            applied[-1] = jsonargparse.Path(str(path), mode="fr")

    def _apply_named(self, parser, cfg, value: str, option_string, source: str) -> None:
        """jsonargparse's config action on ``value``, its refusal (a ``TypeError``) naming ``source``."""
        try:
            super().__call__(parser, cfg, value, option_string)
        except TypeError as err:
            message = str(err).replace('Parser key "config": ', "")
            raise TypeError(message if message.startswith(source) else f"{source}: {message}") from err


def _check_yaml(parser, path: Path) -> None:
    """``parser.error`` naming ``path`` and the line of a YAML syntax error (jsonargparse names neither)."""
    try:
        read_yaml_file(path)
    except InputError as err:
        parser.error(str(err))
    except OSError as err:
        parser.error(f"{path}: cannot read the recipe ({err})")
