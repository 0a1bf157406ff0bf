"""Skeleton Mamba: a Mamba-2 (SSD) backbone for human motion (torch + einops only).

Public API::

    from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig, MixerConfig, ssd

The public names load on first use (PEP 562 module ``__getattr__``): importing the package, or one of its
torch-free modules such as the ``sm`` command table (``sm --help``), imports no torch.
"""

import importlib
import sys
import types

__version__ = "0.1.0.dev0"

# public name -> the module that defines it
_API = {
    "GroupScan": "skeleton_mamba.group_scan",
    "HumanTokenizer": "skeleton_mamba.tokenizer",
    "InverseHumanTokenizer": "skeleton_mamba.tokenizer",
    "JointScan": "skeleton_mamba.joint_scan",
    "Mamba2Mixer": "skeleton_mamba.mixer",
    "MixerConfig": "skeleton_mamba.config",
    "SKELETONS": "skeleton_mamba.skeletons",
    "Skeleton": "skeleton_mamba.skeletons",
    "SkeletonMamba": "skeleton_mamba.model",
    "SkeletonMambaBlock": "skeleton_mamba.block",
    "SkeletonMambaConfig": "skeleton_mamba.config",
    "TemporalScan": "skeleton_mamba.temporal_scan",
    "get_skeleton": "skeleton_mamba.skeletons",
    "ssd": "skeleton_mamba.ssd",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})


class _Package(types.ModuleType):
    """The package's module type: ``skeleton_mamba.ssd`` stays the function.

    The import system binds every submodule it loads on its package; ``ssd`` names both the subpackage
    ``skeleton_mamba.ssd`` and the function it exports, and the public name is the function (as it was
    when the package imported it eagerly). The subpackage stays reachable through ``sys.modules`` and
    ``from skeleton_mamba.ssd import ...``.
    """

    def __setattr__(self, name: str, value) -> None:
        if name == "ssd" and isinstance(value, types.ModuleType):
            value = value.ssd
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
