"""Journey (a): a user's motion file -> ``sm export d.glb`` -> ``sm view d.glb`` -> the page in a browser.

Sources: the real CMU BVH (its own unit), NTU ``.skeleton`` and HumanML3D features of ``../shared/data``, and
generated files in the official formats: a BVH in centimetres and an AIST++ ``.pkl`` (``smpl_trans`` in
``smpl_scaling`` units). Checked as a person would look at them:

- the ``.glb`` (read by the tests' own reader) holds the source's joints in metres (the toolkit's reader is
  the truth for the file formats; the BVH units are checked separately in ``test_units.py``);
- a human figure: joints spanning 1.25 to 2.1 m vertically at the tallest frame (joints end at the head's
  centre and the ankles or toes, 5 to 15 % below a stature of 1.4 to 2.1 m; a unit error gives 30 m or 3 cm);
- in the page (headless Chromium): the joints where the file puts them, the feet near the drawn floor, and
  every joint inside the canvas at every checked time.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

from skeleton_mamba.tasks.motion.formats.bvh import save_bvh, smpl_to_bvh
from skeleton_mamba.tasks.motion.formats.motion_reader import load_joints
from skeleton_mamba.tasks.motion.synthetic.dance import synthesize_dance
from skeleton_mamba.tasks.training.cli import main as sm_main
from tests.helpers.browser_page import Page, browser_or_skip
from tests.helpers.gltf_reader import glb_joint_positions
from tests.helpers.repo import SHARED_DATA

JOINT_SPAN_M = (1.25, 2.1)
FEET_ABOVE_FLOOR_M = 0.15  # the lowest joint (an ankle or toe) at most this far above the floor


def _dance():
    return synthesize_dance(120.0, 3.0, fps=30.0, style="bounce", seed=1)


def _bvh_cm(folder: Path) -> Path:
    motion = _dance()
    return save_bvh(
        folder / "dance_cm.bvh", smpl_to_bvh(motion.poses, motion.root_position(), 30.0, scale=100.0)
    )


def _aistpp(folder: Path) -> Path:
    motion = _dance()
    scaling = 93.4  # AIST++ stores about 90 to 100: smpl_trans / smpl_scaling is metres
    data = {
        "smpl_poses": np.asarray(motion.poses, np.float32).reshape(-1, 72),
        "smpl_trans": (np.asarray(motion.root_position()) * scaling).astype(np.float32),
        "smpl_scaling": np.array([scaling], np.float32),
        "smpl_loss": np.float64(0.01),
    }
    path = folder / "gBR_sBM_cAll_d04_mBR0_ch01.pkl"
    with open(path, "wb") as f:
        pickle.dump(data, f)
    return path


SOURCES = {
    "cmu_bvh": lambda folder: SHARED_DATA / "bvh" / "cmu_01_01.bvh",
    "ntu_skeleton": lambda folder: SHARED_DATA / "ntu" / "S001C001P001R001A001.skeleton",
    "humanml3d_features": lambda folder: SHARED_DATA / "humanml3d" / "new_joint_vecs" / "012314.npy",
    "bvh_centimetres": _bvh_cm,
    "aistpp_pkl": _aistpp,
}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """source name -> (source file, exported .glb, viewer page), made on first use."""
    folder = tmp_path_factory.mktemp("journey_a")
    made: dict[str, tuple[Path, Path, Path]] = {}

    def get(name: str) -> tuple[Path, Path, Path]:
        if name not in made:
            source = SOURCES[name](folder)
            if not source.is_file():
                pytest.skip(f"real sample {source.name} not found under {SHARED_DATA}")
            glb, html = folder / f"{name}.glb", folder / f"{name}.html"
            assert sm_main(["export", str(source), "--out", str(glb)]) == 0
            assert sm_main(["view", str(glb), "--out", str(html)]) == 0
            made[name] = source, glb, html
        return made[name]

    return get


def _span(joints: np.ndarray) -> float:
    """The tallest frame's vertical span of the joints (T, J, 3)."""
    return float((joints[..., 1].max(axis=1) - joints[..., 1].min(axis=1)).max())


@pytest.mark.parametrize("name", SOURCES)
def test_exported_figure_is_a_person_in_metres(exported, name):
    source, glb, _ = exported(name)
    names, positions = glb_joint_positions(glb)
    truth = load_joints(source).joints
    assert positions.shape == truth.shape
    np.testing.assert_allclose(positions, truth, atol=1e-4, rtol=0)
    body = positions[:, :25]  # the first body of a two-body NTU file
    assert JOINT_SPAN_M[0] <= _span(body) <= JOINT_SPAN_M[1], f"{name}: {_span(body):.2f} m"


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    browser_or_skip()
    page = Page("about:blank", tmp_path_factory.mktemp("chromium"))
    yield page
    page.close()


@pytest.mark.parametrize("name", SOURCES)
def test_page_shows_the_whole_figure_on_the_floor(exported, browser, name):
    source, _, html = exported(name)
    browser.open(html.as_uri())
    truth = load_joints(source).joints
    duration = browser.js("window.smViewer.duration")
    floor = browser.js("window.smViewer.floor")
    width, height = browser.js("[window.smViewer.renderer.domElement.clientWidth, "
                               "window.smViewer.renderer.domElement.clientHeight]")  # fmt: skip
    offset = np.asarray(browser.js("window.smViewer.offset(0)"))
    lowest, shown = [], []
    for frame in np.linspace(0, len(truth) - 1, 6).round().astype(int):  # key times: no interpolation
        t = duration * frame / max(len(truth) - 1, 1)
        browser.js(f"window.smViewer.seek({t}); window.smViewer.render()")
        joints = np.asarray(browser.js("window.smViewer.jointsWorld(0)"))
        np.testing.assert_allclose(joints - offset, truth[frame], atol=1e-3, rtol=0)
        pixels = np.asarray([browser.js(f"window.smViewer.project({p.tolist()})") for p in joints])
        inside = (pixels >= 0).all(axis=1) & (pixels[:, 0] <= width) & (pixels[:, 1] <= height)
        assert inside.all(), f"{name} at {t:.2f} s: joints {np.flatnonzero(~inside).tolist()} off the canvas"
        lowest.append(joints[:, 1].min() - floor)
        shown.append(joints[:25])
    assert min(lowest) >= -1e-3, f"{name}: a joint below the floor"
    assert np.median(lowest) <= FEET_ABOVE_FLOOR_M, f"{name}: feet {np.median(lowest):.2f} m above the floor"
    assert JOINT_SPAN_M[0] - 0.2 <= _span(np.stack(shown)) <= JOINT_SPAN_M[1]
    assert not browser.errors, browser.errors
