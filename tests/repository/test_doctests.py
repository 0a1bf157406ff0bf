"""What the examples cover: every public name of the backbone, and every reader and metric of the toolkit, has
one in its docstring, and every module holding ``>>>`` has examples doctest finds. The examples themselves run
as pytest's doctest items (``tests/repository/conftest.py``, collected beside this file).
"""

from __future__ import annotations

import doctest
import importlib

import pytest

import skeleton_mamba
import skeleton_mamba.tasks.motion.metrics as toolkit_metrics
from tests.repository.conftest import modules_with_examples

API = skeleton_mamba._API  # public name -> the module that defines it


EXAMPLES = list(modules_with_examples())


def test_the_walk_reaches_the_examples_of_every_layer():
    assert {"skeleton_mamba.model", "skeleton_mamba.ssd.minimal", "skeleton_mamba.pretrained.codec"} <= set(
        EXAMPLES
    )
    for room in ("formats", "io", "music", "metrics"):
        assert any(name.startswith(f"skeleton_mamba.tasks.motion.{room}.") for name in EXAMPLES), room


@pytest.mark.parametrize("module_name", EXAMPLES)
def test_every_module_with_an_example_has_doctests(module_name):
    """A ``>>>`` that doctest does not find (in a comment, in a string that is not a docstring) never runs."""
    module = importlib.import_module(module_name)
    assert any(t.examples for t in doctest.DocTestFinder().find(module)), (
        f"{module_name} holds '>>>' but doctest finds no example in it"
    )


@pytest.mark.parametrize("name", sorted(API))
def test_every_public_name_has_an_example(name):
    module = importlib.import_module(API[name])
    if name == "ssd":
        module = importlib.import_module("skeleton_mamba.ssd.dispatch")
    examples = [t for t in doctest.DocTestFinder().find(module) if t.examples]
    assert any(name in example.source for t in examples for example in t.examples), (
        f"{name}: no example in {module.__name__} uses it"
    )


# The toolkit's readers and metrics (and the backbone's bounded reader they use): module -> the names that
# must each have an example.
MOTION = "skeleton_mamba.tasks.motion"
READERS = {
    "skeleton_mamba.io.bounded_read": (
        "check_json_depth",
        "parse_json",
        "read_bytes",
        "read_json",
        "read_text",
    ),
    f"{MOTION}.formats.aistpp": ("load_aistpp_motion", "load_split"),
    f"{MOTION}.music.audio_io": ("open_audio", "open_wav_stream", "probe_audio", "read_audio"),
    f"{MOTION}.formats.bvh": ("load_bvh", "save_bvh"),
    f"{MOTION}.formats.gltf_read": ("read_glb",),
    f"{MOTION}.formats.humanml3d_features": ("read_feature_vector", "read_features", "read_statistics"),
    f"{MOTION}.formats.motion_file": ("load_motion", "save_motion"),
    f"{MOTION}.formats.motion_reader": ("load_joints", "load_skeleton_motion"),
    f"{MOTION}.formats.ntu": ("parse_ntu_name", "read_skeleton_file"),
    f"{MOTION}.io.safe_pickle": ("safe_load_pickle", "safe_loads_pickle"),
    f"{MOTION}.io.value_checks": ("load_npy", "load_npz"),
}
METRICS = {
    f"{MOTION}.metrics.beat_align": (
        "BeatAlign",
        "alignment_score",
        "kinematic_beats",
        "sequence_beat_align",
    ),
    f"{MOTION}.metrics.dynamics": (
        "dynamics_checks",
        "dynamics_ratios",
        "high_frequency_energy",
        "motion_amplitude",
        "motion_jitter",
    ),
    f"{MOTION}.metrics.evaluation": ("DanceEvaluation",),
    f"{MOTION}.metrics.fid": (
        "FrechetMotionDistance",
        "MotionDiversity",
        "average_pairwise_distance",
        "frechet_distance",
        "motion_features",
        "normalise_by_reference",
    ),
    f"{MOTION}.metrics.geometric": ("geometric_features",),
    f"{MOTION}.metrics.ground": ("foot_skating_ratio", "ground_penetration"),
    f"{MOTION}.metrics.held_out_dynamics": (
        "format_dynamics",
        "held_out_dynamics",
        "held_out_dynamics_checks",
    ),
    f"{MOTION}.metrics.kinetic": ("kinetic_features",),
    f"{MOTION}.metrics.mmv": ("MMV", "flow_magnitudes", "load_video_frames", "visual_beats"),
    f"{MOTION}.metrics.pfc": ("PFC", "pfc_sequence_score"),
    f"{MOTION}.metrics.pose_distance": (
        "canonical_poses",
        "mpjpe",
        "nearest_pose_distance",
        "pose_set_distance",
    ),
    f"{MOTION}.metrics.protocols": ("get_protocol",),
}
TOOLKIT = {**READERS, **METRICS}


@pytest.mark.parametrize(
    ("module_name", "name"), sorted((module, name) for module, names in TOOLKIT.items() for name in names)
)
def test_every_toolkit_reader_and_metric_has_an_example(module_name, name):
    module = importlib.import_module(module_name)
    owner = getattr(module, name)
    tests = doctest.DocTestFinder(recurse=False).find(owner, name, module=module)
    examples = [example for test in tests for example in test.examples]
    assert any(name in example.source for example in examples), (
        f"{module_name}.{name}: its docstring has no example that uses it"
    )


def test_every_public_metric_is_listed():
    """Each class and function the metrics package exports is in :data:`METRICS` (so it has an example)."""
    listed = {name for names in METRICS.values() for name in names}
    exported = {
        name
        for name in toolkit_metrics.__all__
        if callable(getattr(toolkit_metrics, name)) and not name.isupper()
    }
    assert exported - listed == set()
