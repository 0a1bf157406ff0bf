"""Dance metrics as torchmetrics ``Metric`` subclasses (usable from any LightningModule).

======================  =====================================================  ==========================
metric                  class                                                  source
======================  =====================================================  ==========================
FID_k / FID_g           ``FrechetMotionDistance(feature="kinetic"|"geometric")``  FACT / Bailando scripts
Div_k / Div_g           ``MotionDiversity(feature="kinetic"|"geometric")``        FACT / Bailando scripts
BeatAlign               ``BeatAlign(variant="fact"|"bailando")``                  FACT / Bailando scripts
PFC                     ``PFC()``                                                 EDGE eval_pfc.py
MMV                     ``MMV()``                                                 [EgoMusic] supp. 7.1
======================  =====================================================  ==========================

Feature functions: :func:`kinetic_features` (72-d), :func:`geometric_features` (32-d).
Named evaluation protocols ``fact | bailando | edge`` (frames, music beats, BeatAlign form per paper):
:func:`get_protocol`, and :class:`DanceEvaluation` for a whole table row.
"""

from skeleton_mamba.tasks.motion.metrics.beat_align import BeatAlign, alignment_score, kinematic_beats
from skeleton_mamba.tasks.motion.metrics.evaluation import DanceEvaluation
from skeleton_mamba.tasks.motion.metrics.fid import (
    FrechetMotionDistance,
    MotionDiversity,
    average_pairwise_distance,
    frechet_distance,
    motion_features,
)
from skeleton_mamba.tasks.motion.metrics.geometric import geometric_features
from skeleton_mamba.tasks.motion.metrics.kinetic import kinetic_features
from skeleton_mamba.tasks.motion.metrics.mmv import MMV, flow_magnitudes, visual_beats
from skeleton_mamba.tasks.motion.metrics.pfc import PFC
from skeleton_mamba.tasks.motion.metrics.protocols import PROTOCOLS, get_protocol

__all__ = [
    "MMV",
    "PFC",
    "PROTOCOLS",
    "BeatAlign",
    "DanceEvaluation",
    "FrechetMotionDistance",
    "MotionDiversity",
    "alignment_score",
    "average_pairwise_distance",
    "flow_magnitudes",
    "frechet_distance",
    "geometric_features",
    "get_protocol",
    "kinematic_beats",
    "kinetic_features",
    "motion_features",
    "visual_beats",
]
