"""What a recipe may name and how large its numbers may be (``sm fit|validate|test|predict``).

**Class paths.** jsonargparse imports every class path a recipe, a ``--config`` file or a dotted option names
(``class_path: pkg.mod.Cls``, ``--model pkg.mod.Cls``, a callable given by its path), and importing a module
runs it. Recipes get the checkpoints' policy
(:data:`~skeleton_mamba.tasks.training.checkpoints.TRUSTED_CLASS_PREFIXES`: the project's modules and the
Lightning, ``torch.optim``, ``torch.nn`` and torchmetrics classes recipes use, and the packages of the
registered tasks): any other module is refused before it is imported, unless the user trusts it explicitly
with ``--allow-import MODULE`` (repeatable) or ``SM_ALLOW_IMPORT=mod1,mod2``. jsonargparse's own deny-list
(``os``, ``subprocess``, ``builtins.exec``, ...) stays on top: it cannot be allowed. The check is
jsonargparse's import-path policy (:func:`~skeleton_mamba.tasks.training.lightning_compat.import_policy`),
which looks at the path before the import and at the imported object's defining module after it.

**Numbers.** Values the trainer, the seed and the task modules use are range-checked once parsed, before
anything uses them (:func:`check_config_values`): a 24-digit seed, ``--trainer.max_epochs 1e30``, a batch
size of 0 or a frame count of 1e14 are one-line :class:`~skeleton_mamba.errors.InputError`\\ s
naming the option and the recipes it may come from, instead of a numpy ``ValueError``, an ``OverflowError`` or
a 728 TiB allocation. Every float is finite (a ``guidance_weight: .nan`` or an ``eta: .inf`` is refused at
once, not after minutes of training by the demo that samples with it; only a mixer's ``dt_limit`` max may be
``inf``), every diffusion sampler named (``sampler``, ``eval_sampler``) is one of
:data:`~skeleton_mamba.tasks.training.sampler_registry.SAMPLERS`, and every sampling step count fits the
model's ``diffusion_steps``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

from lightning.fabric.utilities.seed import max_seed_value, min_seed_value

from skeleton_mamba.errors import InputError
from skeleton_mamba.pretrained.size_bounds import SIZE_BOUNDS
from skeleton_mamba.tasks.motion.io.option_types import MAX_FRAMES, MAX_IMAGE_SIZE, MAX_WORKERS
from skeleton_mamba.tasks.motion.io.value_checks import FPS_RANGE
from skeleton_mamba.tasks.training.checkpoints import TRUSTED_CLASS_PREFIXES, trusted_class_prefixes
from skeleton_mamba.tasks.training.sampler_registry import SAMPLERS, get_sampler

__all__ = [
    "ALLOW_IMPORT_ENV",
    "ALLOW_IMPORT_OPTION",
    "MAX_BATCH_SIZE",
    "MAX_COUNT",
    "MAX_FRAMES",
    "MAX_OPTION_DURATION_S",
    "TRUSTED_MODULES",
    "check_allowed_modules",
    "check_config_values",
    "split_allow_import",
    "trusted_modules",
]

ALLOW_IMPORT_OPTION = "--allow-import"
ALLOW_IMPORT_ENV = "SM_ALLOW_IMPORT"
TRUSTED_MODULES: tuple[str, ...] = tuple(prefix.rstrip(".") for prefix in TRUSTED_CLASS_PREFIXES)
"""The modules a recipe's class paths may name without an opt-in (those of the checkpoint policy)."""

MAX_COUNT = 2**31 - 1  # epochs, steps, intervals: a C int, what Lightning's loops, torch and numpy index with
MAX_BATCH_SIZE = 1 << 16  # samples per batch
MAX_SAMPLES = 10_000_000  # sample counts of generated data sets (per class, clips, sequences)
MAX_CLASSES = 100_000
MAX_OPTION_DURATION_S = 86_400.0  # durations given in seconds (generated tracks, offsets): one day
MAX_TIME_DAYS = 3650  # --trainer.max_time: ten years
_INT64 = 2**63 - 1
INFINITE_ALLOWED = frozenset({"dt_limit[1]"})
"""The floats that may be ``inf`` (by their last key): a mixer's ``dt_limit = (0, inf)`` (no clamp). No float
may be NaN, and no other may be infinite."""
SAMPLER_KEYS = frozenset({"sampler", "eval_sampler"})  # diffusion samplers (tasks/training/diffusion)
STEP_KEYS = {"sampling_steps": "sampler", "eval_sampling_steps": "eval_sampler"}  # steps -> their sampler


def split_allow_import(args: Sequence[str]) -> tuple[list[str], tuple[str, ...]]:
    """``args`` without ``--allow-import MODULE`` / ``--allow-import=MODULE``, and those modules followed by
    the entries of ``SM_ALLOW_IMPORT`` (comma-separated)."""
    rest: list[str] = []
    modules: list[str] = []
    items = iter(args)
    for arg in items:
        if arg == ALLOW_IMPORT_OPTION:
            value = next(items, None)
            if value is None:
                raise InputError(
                    f"{ALLOW_IMPORT_OPTION} needs a module name (e.g. {ALLOW_IMPORT_OPTION} my_pkg)"
                )
            modules.append(value)
        elif arg.startswith(ALLOW_IMPORT_OPTION + "="):
            modules.append(arg.split("=", 1)[1])
        else:
            rest.append(arg)
    modules += [m.strip() for m in os.environ.get(ALLOW_IMPORT_ENV, "").split(",") if m.strip()]
    return rest, tuple(dict.fromkeys(modules))


def check_allowed_modules(allowed: Sequence[str]) -> tuple[str, ...]:
    """:data:`TRUSTED_MODULES` and the opted-in ``allowed`` modules, for
    :func:`~skeleton_mamba.tasks.training.lightning_compat.import_policy`.

    Raises:
        InputError: an entry of ``allowed`` is not a dotted module name, or is jsonargparse itself.
    """
    for module in allowed:
        if not module or not all(part.isidentifier() for part in module.split(".")):
            raise InputError(
                f"{ALLOW_IMPORT_OPTION} / {ALLOW_IMPORT_ENV}: {module!r} is not a module name "
                "(e.g. my_pkg.models)"
            )
        if module == "jsonargparse" or module.startswith("jsonargparse."):
            raise InputError(f"{ALLOW_IMPORT_OPTION} / {ALLOW_IMPORT_ENV}: jsonargparse cannot be allowed")
    return (*trusted_modules(), *allowed)


def trusted_modules() -> tuple[str, ...]:
    """:data:`TRUSTED_MODULES` and the registered tasks' packages
    (:func:`~skeleton_mamba.tasks.training.checkpoints.trusted_class_prefixes`)."""
    return tuple(prefix.rstrip(".") for prefix in trusted_class_prefixes())


def refused_import_message(path: str) -> str:
    """The one-line refusal of class path ``path``, saying how to trust its module."""
    top = path.split(".")[0]
    return (
        f"class path {path!r} is outside the project's modules ({', '.join(trusted_modules())}); "
        f"refusing to import it (trust it with {ALLOW_IMPORT_OPTION} {top} or {ALLOW_IMPORT_ENV}={top})"
    )


# --- numeric ranges -----------------------------------------------------------------------------


def _count(low: int, high: int = MAX_COUNT, *, also: tuple[int, ...] = ()) -> tuple:
    return ("int", low, high, also)


def _real(low: float, high: float, *, low_open: bool = False) -> tuple:
    return ("real", low, high, low_open)


def _batches() -> tuple:  # Lightning's limit_*_batches: a count, or a fraction of the loader
    return ("batches", 0, MAX_COUNT, False)


# --trainer.<key> -> rule
TRAINER_RULES: dict[str, tuple] = {
    "max_epochs": _count(0, also=(-1,)),
    "min_epochs": _count(0),
    "max_steps": _count(0, also=(-1,)),
    "min_steps": _count(0),
    "log_every_n_steps": _count(0),
    "check_val_every_n_epoch": _count(1),
    "accumulate_grad_batches": _count(1),
    "num_sanity_val_steps": _count(0, also=(-1,)),
    "reload_dataloaders_every_n_epochs": _count(0),
    "num_nodes": _count(1),
    "fast_dev_run": _count(0),
    "limit_train_batches": _batches(),
    "limit_val_batches": _batches(),
    "limit_test_batches": _batches(),
    "limit_predict_batches": _batches(),
    "val_check_interval": ("batches", 1, MAX_COUNT, True),
    "gradient_clip_val": _real(0.0, 1e6),
}


def _init_arg_rule(name: str) -> tuple | None:
    """The range of a model / data / optimizer argument called ``name`` (None: only the generic bounds)."""
    if name in ("batch_size", "test_batch_size", "base_batch_size") or name.endswith("_batch_size"):
        return _count(1, MAX_BATCH_SIZE)
    if name == "num_workers":
        return _count(0, MAX_WORKERS)
    if name == "fps":
        return _real(*FPS_RANGE)
    if name == "seed":
        return _count(min_seed_value, max_seed_value)
    if name in ("num_frames", "clip_len", "window", "window_frames", "max_frames"):
        return _count(1, MAX_FRAMES)
    if name.endswith("_frames") or name in ("stride", "window_stride"):
        return _count(0, MAX_FRAMES)
    if name.endswith("_per_class") or name in ("count", "limit") or name.endswith(("_count", "_clips")):
        return _count(0, MAX_SAMPLES)
    if name.startswith("num_clips") or name.endswith("_sequences"):
        return _count(0, MAX_SAMPLES)
    if name in ("image_size", "frame_size"):
        return _count(1, MAX_IMAGE_SIZE)
    if name == "num_classes":
        return _count(1, MAX_CLASSES)
    if name in ("diffusion_steps", *STEP_KEYS):
        return _count(1, SIZE_BOUNDS[name if name == "diffusion_steps" else "sampling_steps"])
    if name.endswith("_s") and not name.endswith("_steps"):  # a duration or offset in seconds
        return _real(0.0, MAX_OPTION_DURATION_S)
    if name == "lr" or name.endswith("_lr"):
        return _real(0.0, 1e3, low_open=True)
    if name == "weight_decay":
        return _real(0.0, 1e3)
    if name.endswith("_fraction"):
        return _real(0.0, 1.0)
    return None


def _describe(rule: tuple) -> str:
    kind, low, high, extra = rule
    if kind == "int":
        alternatives = "".join(f"{a}, or " for a in extra)
        return f"an integer, {alternatives}{low:,} to {high:,}"
    if kind == "batches":
        low_fraction = "above 0" if extra else "from 0"
        return f"an integer {low:,} to {high:,}, or a fraction {low_fraction} to 1.0"
    return f"a number {'above' if extra else 'from'} {low:g} to {high:g}"


def _in_range(value: Any, rule: tuple) -> bool:
    kind, low, high, extra = rule
    if kind == "int":
        return isinstance(value, int) and (value in extra or low <= value <= high)
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return False
    if kind == "batches":
        if isinstance(value, int):
            return low <= value <= high
        return (0.0 < value if extra else 0.0 <= value) and value <= 1.0
    return (low < value if extra else low <= value) and value <= high


def _max_time_problem(value: Any) -> str | None:
    """Why a ``--trainer.max_time`` (``DD:HH:MM:SS`` or a dict of timedelta fields) is refused, or None."""
    if value is None:
        return None
    scale = {"weeks": 7 * 86_400, "days": 86_400, "hours": 3600, "minutes": 60, "seconds": 1}
    if isinstance(value, str):
        parts = value.split(":")
        if len(parts) != 4 or not all(p.strip().isdigit() for p in parts):
            return "is not DD:HH:MM:SS"
        seconds = sum(int(p) * s for p, s in zip(parts, (86_400, 3600, 60, 1)))
    elif isinstance(value, Mapping):
        if not set(value) <= set(scale) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0
            for v in value.values()
        ):
            return f"is not a mapping of non-negative {', '.join(scale)}"
        seconds = sum(v * scale[k] for k, v in value.items())
    else:
        return None  # a timedelta built in code
    if seconds > MAX_TIME_DAYS * 86_400:
        return f"is more than {MAX_TIME_DAYS:,} days"
    return None


def _leaves(value: Any, where: str) -> Iterator[tuple[str, str, Any]]:
    """``(dotted option, last key, value)`` of every number under ``value`` (mappings and lists)."""
    if isinstance(value, Mapping):
        for key, item in value.items():
            if isinstance(key, str) and not key.startswith("__"):
                yield from _leaves(item, f"{where}.{key}" if where else key)
    elif isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            yield from _leaves(item, f"{where}[{i}]")
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield where, where.rsplit(".", 1)[-1], value


def check_config_values(config: Mapping[str, Any], sources: Sequence[str] = ()) -> None:
    """Refuse a parsed subcommand config holding a number out of its range, before anything uses it.

    ``config`` is the subcommand's part as a dict (``trainer``, ``model``, ``data``, ``seed_everything``,
    ...); ``sources`` are the recipes and config files it was read from, named in the message.

    Rules: :data:`TRAINER_RULES` for ``trainer.*``, Lightning's seed range for ``seed_everything``, the
    argument-name ranges of :func:`_init_arg_rule` for everything else, and any integer within a signed
    64 bits (floats without a rule may be infinite: ``dt_limit = (0, inf)``).

    Raises:
        InputError: ``--<option> = value: expected ...`` naming where the value may come from.
    """
    origin = f" (from {', '.join(sources)} or the command line)" if sources else ""

    def refuse(option: str, value: Any, expected: str) -> None:
        shown = repr(value) if len(repr(value)) <= 40 else repr(value)[:37] + "..."
        raise InputError(f"--{option} = {shown}: expected {expected}{origin}")

    seed = config.get("seed_everything")
    if seed is not None and not isinstance(seed, bool):
        if not isinstance(seed, int) or not min_seed_value <= seed <= max_seed_value:
            refuse(
                "seed_everything", seed, f"true, false or an integer {min_seed_value} to {max_seed_value:,}"
            )
    trainer = config.get("trainer") or {}
    problem = _max_time_problem(trainer.get("max_time")) if isinstance(trainer, Mapping) else None
    if problem is not None:
        raise InputError(f"--trainer.max_time = {trainer.get('max_time')!r}: {problem}{origin}")
    for section, value in config.items():
        if section == "seed_everything":
            continue
        for option, name, number in _leaves(value, section):
            rule = TRAINER_RULES.get(name) if option == f"trainer.{name}" else None
            if rule is None and section != "trainer":
                rule = _init_arg_rule(name)
            if rule is not None and not _in_range(number, rule):
                refuse(option, number, _describe(rule))
            if isinstance(number, int) and abs(number) > _INT64:
                refuse(option, number, f"an integer within ±{_INT64:,}")
            if isinstance(number, float) and not math.isfinite(number):
                if not (number == math.inf and name in INFINITE_ALLOWED):
                    raise InputError(f"--{option} = {number}: must be a finite number{origin}")
    _check_sampling(config, origin)


def _mappings(value: Any, where: str) -> Iterator[tuple[str, Mapping]]:
    """``(dotted option, mapping)`` of every mapping under ``value`` (itself included)."""
    if isinstance(value, Mapping):
        yield where, value
        for key, item in value.items():
            if isinstance(key, str) and not key.startswith("__"):
                yield from _mappings(item, f"{where}.{key}" if where else key)
    elif isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            yield from _mappings(item, f"{where}[{i}]")


def _check_sampling(config: Mapping[str, Any], origin: str) -> None:
    """The diffusion samplers and step counts of a parsed config (the model's and its callbacks'): every
    ``sampler`` / ``eval_sampler`` one of :data:`SAMPLERS`, every step count within what its sampler takes on
    the model's ``model.init_args.diffusion_steps`` T (DDIM 1 to T, the solvers 2 to T; DDPM runs all T and
    takes none). A step count given without a sampler (a callback's, ``eval_sampling_steps``) samples DDIM.

    Raises:
        InputError: ``--<option> = value: ...`` naming the sampler names or the range.
    """
    model = config.get("model")
    init = model.get("init_args") if isinstance(model, Mapping) else None
    steps = init.get("diffusion_steps") if isinstance(init, Mapping) else None
    total = steps if isinstance(steps, int) and not isinstance(steps, bool) and steps >= 1 else None
    for section, value in config.items():
        if section == "data":
            continue
        for where, mapping in _mappings(value, section):
            for key, item in mapping.items():
                if key in SAMPLER_KEYS and item is not None and item not in SAMPLERS:
                    names = ", ".join(SAMPLERS.names())
                    raise InputError(
                        f"--{where}.{key} = {item!r}: expected a sampler, one of {names}{origin}"
                    )
            if total is None:
                continue
            for key, sampler_key in STEP_KEYS.items():
                count = mapping.get(key)
                if not isinstance(count, int) or isinstance(count, bool):
                    continue
                name = mapping.get(sampler_key) or "ddim"
                low = get_sampler(name).first_step
                if low is None:
                    continue  # runs all T steps (DDPM)
                if not low <= count <= total:
                    raise InputError(
                        f"--{where}.{key} = {count}: {name} takes {low} to {total} steps on this model "
                        f"(--model.init_args.diffusion_steps = {total}){origin}"
                    )
