"""The registries of what users add (``skeleton_mamba/registry.py``): a sampler and a motion format are each
one object and one line, found by every path that takes their name, and an unknown name is refused listing
the registered ones."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import tomllib
import torch

from skeleton_mamba.registry import Registry, UnknownNameError
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints, load_skeleton_motion
from skeleton_mamba.tasks.motion.formats.registry import (
    MOTION_FORMATS,
    FileMotion,
    JointsClip,
    ReadRequest,
)
from skeleton_mamba.tasks.training.diffusion.gaussian import GaussianDiffusion
from skeleton_mamba.tasks.training.diffusion.sampling import SamplingOptions, sample
from skeleton_mamba.tasks.training.sampler_registry import SAMPLERS, Sampler, get_sampler

REPO = Path(__file__).resolve().parents[2]


# --------------------------------------------------------------------------------------------- the registry
def test_a_registry_registers_where_defined_and_refuses_what_it_does_not_know():
    shapes = Registry("shape")
    square = shapes.register("square")(lambda side: side * side)
    shapes.register("circle")(lambda r: 3.0 * r * r)
    assert shapes.names() == ("square", "circle") and shapes.get("square") is square
    assert "square" in shapes and "triangle" not in shapes and 3 not in shapes
    with pytest.raises(ValueError, match="'square' is registered already"):
        shapes.register("square")(lambda side: 0)
    shapes.register("square", force=True)(abs)
    assert shapes.get("square") is abs and shapes.names() == ("square", "circle")
    with pytest.raises(UnknownNameError) as err:
        shapes.get("triangle")
    assert str(err.value) == "shape must be one of square, circle, got 'triangle'"
    assert isinstance(err.value, KeyError) and isinstance(err.value, ValueError)
    shapes.unregister("circle")
    assert shapes.names() == ("square",)
    with pytest.raises(KeyError):
        shapes.unregister("circle")
    with pytest.raises(ValueError, match="non-empty name"):
        shapes.register("")


def test_a_registry_imports_its_locations_on_the_first_lookup_only(tmp_path, monkeypatch):
    (tmp_path / "registry_location_probe.py").write_text(
        textwrap.dedent(
            """
            from tests_registry_probe_home import FRUITS

            @FRUITS.register("apple")
            def apple():
                return "apple"
            """
        )
    )
    fruits = Registry("fruit", locations=["registry_location_probe"])
    home = type(sys)("tests_registry_probe_home")
    home.FRUITS = fruits
    monkeypatch.setitem(sys.modules, "tests_registry_probe_home", home)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "registry_location_probe", raising=False)
    assert "registry_location_probe" not in sys.modules  # not at construction
    assert fruits.get("apple")() == "apple" and fruits.names() == ("apple",)
    assert "registry_location_probe" in sys.modules


# ------------------------------------------------------------------------------------------------ samplers
def test_the_samplers_are_the_entry_points_and_are_listed_without_torch():
    """``sm generate --help`` lists them: the names come from the packaging metadata, not from importing."""
    declared = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["entry-points"]
    names = tuple(sorted(declared["skeleton_mamba.samplers"]))
    code = (
        "import json, sys\n"
        "from skeleton_mamba.tasks.training.sampler_registry import SAMPLERS\n"
        "print(json.dumps([SAMPLERS.names(), 'torch' in sys.modules]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    listed, torch_loaded = json.loads(out)
    assert tuple(listed) == names == ("ddim", "ddpm", "dpmpp", "unipc") and not torch_loaded
    for name in names:
        assert isinstance(get_sampler(name), Sampler)
    assert get_sampler("ddpm").first_step is None and get_sampler("dpmpp").first_step == 2
    assert get_sampler("ddim").uses_eta and not get_sampler("unipc").uses_eta


@pytest.fixture
def one_shot():
    """A sampler defined in one object and registered in one line: x0_hat of pure noise at t = T - 1."""

    def run(diffusion, denoiser, shape, cond=None, *, sampling_steps, eta, generator=None, **options):
        x = torch.randn(shape, generator=generator)
        t = torch.full((shape[0],), diffusion.num_steps - 1, dtype=torch.long)
        return denoiser(x, t, cond) * sampling_steps  # the count reaches it

    SAMPLERS.register("one_shot")(Sampler(run=run, first_step=1, default_steps=3))
    yield
    SAMPLERS.unregister("one_shot")


def test_a_registered_sampler_is_run_and_checked_by_every_path(one_shot):
    diffusion = GaussianDiffusion(8)

    def denoiser(x, t, cond):
        return torch.full_like(x, 0.5) + (0.0 if cond is None else cond)

    out = sample(
        diffusion, denoiser, (2, 3), torch.tensor(1.0), sampler="one_shot", sampling_steps=2, eta=0.0
    )
    assert torch.equal(out, torch.full((2, 3), 3.0))
    options = SamplingOptions("one_shot", 4, 0.3, 2.0)
    assert options.describe() == {"sampler": "one_shot", "sampling_steps": 4, "guidance_weight": 2.0}
    assert options.step_range(8) == (1, 8)
    assert options.steps_problem(3) == "one_shot takes 1 to 3 steps on a model of 3 diffusion steps"
    with pytest.raises(ValueError, match="sampling_steps = 4: one_shot takes 1 to 3 steps"):
        options.check_steps(3)
    # chosen without a count over a sampler with no default of its own: its default; over a solver's: kept
    assert SamplingOptions("ddpm").override(sampler="one_shot").sampling_steps == 3
    assert SamplingOptions("ddim", 50).override(sampler="one_shot").sampling_steps == 3
    assert SamplingOptions("dpmpp", 12).override(sampler="one_shot").sampling_steps == 12
    assert SamplingOptions("ddim", 50).override(sampler="one_shot", sampling_steps=7).sampling_steps == 7
    with pytest.raises(ValueError, match="must be one of ddim, ddpm, dpmpp, unipc, one_shot, got 'two'"):
        SamplingOptions("two")


def test_a_recipe_names_a_registered_sampler_or_is_refused(one_shot):
    from skeleton_mamba.errors import InputError
    from skeleton_mamba.tasks.training.recipe_policy import _check_sampling

    config = {"model": {"init_args": {"diffusion_steps": 10, "sampler": "one_shot", "sampling_steps": 10}}}
    _check_sampling(config, "")
    config["model"]["init_args"]["sampling_steps"] = 11
    with pytest.raises(InputError, match="one_shot takes 1 to 10 steps"):
        _check_sampling(config, "")
    config["model"]["init_args"].update(sampler="euler", sampling_steps=5)
    with pytest.raises(InputError, match="expected a sampler, one of ddim, ddpm, dpmpp, unipc, one_shot"):
        _check_sampling(config, "")


# ------------------------------------------------------------------------------------------ motion formats
def test_the_built_in_motion_formats_are_registered_by_their_modules():
    assert set(MOTION_FORMATS.names()) == {".npz", ".pkl", ".npy", ".bvh", ".skeleton", ".glb"}
    for name in MOTION_FORMATS.names():
        fmt = MOTION_FORMATS.get(name)
        assert fmt.read.__module__.startswith("skeleton_mamba.tasks.motion.formats.") and fmt.reads


@pytest.fixture
def csv_format():
    """A new motion format in one function and one line: joint positions as CSV rows of J * 3 values."""

    @MOTION_FORMATS.register(".jcsv")
    def read_csv_joints(path: Path, request: ReadRequest) -> FileMotion:
        """joint positions, one CSV row of J x 3 values per frame"""
        rows = np.loadtxt(path, delimiter=",", ndmin=2)
        joints = rows.reshape(len(rows), -1, 3)
        parents = [-1] + list(range(joints.shape[1] - 1))  # a chain
        names = [f"j{i}" for i in range(joints.shape[1])]
        return FileMotion(JointsClip(joints, parents, names, request.motion_fps or 25.0))

    yield
    MOTION_FORMATS.unregister(".jcsv")


def test_a_registered_motion_format_is_read_by_both_views_with_units(csv_format, tmp_path):
    frames = np.stack([np.array([[0, 0, 0], [0, 50, 0], [0, 100, 0]]) + [k, 0, 0] for k in range(4)], 0)
    path = tmp_path / "chain.JCSV"  # the suffix in any case
    np.savetxt(path, frames.reshape(4, -1), delimiter=",")
    clip = load_joints(path, units="cm")
    assert clip.fps == 25.0 and clip.names == ["j0", "j1", "j2"] and clip.parents == [-1, 0, 1]
    np.testing.assert_allclose(clip.joints, frames / 100.0)
    motion = load_skeleton_motion(path, motion_fps=50.0, units="cm")
    assert motion.fps == 50.0 and motion.names == ["j0", "j1", "j2"]
    np.testing.assert_allclose(motion.joint_positions(), frames / 100.0, atol=1e-9)


def test_an_unregistered_suffix_is_refused_naming_the_file_and_the_formats(tmp_path):
    path = tmp_path / "dance.fbx"
    path.write_bytes(b"Kaydara FBX Binary  \x00")
    with pytest.raises(ValueError) as err:
        load_joints(path)
    message = str(err.value)
    assert str(path) in message and "'.fbx'" in message
    assert all(name in message for name in MOTION_FORMATS.names())
    with pytest.raises(ValueError, match="lower-case suffix"):
        MOTION_FORMATS.register("csv")
