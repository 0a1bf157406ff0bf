"""Skeleton Mamba: a Mamba-2 (SSD) backbone for human motion (torch + einops only).

Public API::

    from skeleton_mamba import SkeletonMamba, SkeletonMambaConfig, MixerConfig, ssd
"""

__version__ = "0.1.0.dev0"

from skeleton_mamba.block import SkeletonMambaBlock
from skeleton_mamba.config import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.group_scan import GroupScan
from skeleton_mamba.joint_scan import JointScan
from skeleton_mamba.mixer import Mamba2Mixer
from skeleton_mamba.model import SkeletonMamba
from skeleton_mamba.skeletons import SKELETONS, Skeleton, get_skeleton
from skeleton_mamba.ssd import ssd
from skeleton_mamba.temporal_scan import TemporalScan
from skeleton_mamba.tokenizer import HumanTokenizer, InverseHumanTokenizer

__all__ = [
    "__version__",
    "GroupScan",
    "HumanTokenizer",
    "InverseHumanTokenizer",
    "JointScan",
    "Mamba2Mixer",
    "MixerConfig",
    "SKELETONS",
    "Skeleton",
    "SkeletonMamba",
    "SkeletonMambaBlock",
    "SkeletonMambaConfig",
    "TemporalScan",
    "get_skeleton",
    "ssd",
]
