"""Fuzzing the readers of outside data: a corrupted real sample parses correctly or raises DataFileError.

Random corruptions (poison numbers such as NaN, Inf and 1e999, deleted, repeated or garbled lines,
truncation, flipped bytes, replaced JSON values) of the real samples in ``../shared/data`` and of a
Kinetics-skeleton clip written here in the ST-GCN layout. Any other exception fails the test, and a
successful parse must hold only finite numbers of consistent shapes.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skeleton_mamba.errors import DataFileError
from skeleton_mamba.tasks.motion.formats.bvh import load_bvh
from skeleton_mamba.tasks.motion.formats.humanml3d_features import FEATURE_DIM, read_features
from skeleton_mamba.tasks.motion.formats.ntu import read_skeleton_file
from skeleton_mamba.tasks.recognition.kinetics import NUM_JOINTS as KINETICS_JOINTS
from skeleton_mamba.tasks.recognition.kinetics import read_kinetics_clip
from tests.helpers.repo import shared_file

FUZZ = settings(max_examples=60, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])  # fmt: skip
NAN, INF = float("nan"), float("inf")
POISON = ["nan", "NaN", "inf", "-inf", "1e999", "-1e999", "1e39", "", "x", "1.2.3", "9" * 20, "-1", "0"]


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _mutate_lines(data: st.DataObject, lines: list[str], numeric: list[int]) -> str:
    """Apply 1-2 random corruptions to ``lines`` (``numeric``: indices of lines of numbers).

    Places are drawn uniformly (hypothesis' integers favour small values, i.e. the first lines); a
    poison replaces one number of a numeric line.
    """
    lines = list(lines)
    rng = data.draw(st.randoms(use_true_random=False))
    for _ in range(data.draw(st.integers(1, 2))):
        if not lines:
            break
        kind = data.draw(st.sampled_from(["poison"] * 3 + ["delete", "repeat", "garble", "truncate"]))
        i = rng.choice(numeric) if kind == "poison" else rng.randrange(len(lines))
        if i >= len(lines):
            continue
        if kind == "poison":
            tokens = lines[i].split()
            places = [k for k, token in enumerate(tokens) if _is_number(token)]
            if places:
                tokens[rng.choice(places)] = data.draw(st.sampled_from(POISON))
                lines[i] = " ".join(tokens)
        elif kind == "delete":
            del lines[i]
        elif kind == "repeat":
            lines.insert(i, lines[i])
        elif kind == "garble":
            lines[i] = data.draw(st.text(max_size=20))
        else:
            lines = lines[:i] + [lines[i][: rng.randrange(len(lines[i]) + 1)]]
    return "\n".join(lines)


def _read(read, name: str, content: str | bytes):
    """``read(path)`` of ``content`` written to a temporary file, or ``None`` when it raises DataFileError."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / name
        path.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8", "surrogatepass"))
        try:
            return read(path)
        except DataFileError:
            return None


def test_ntu_reader_survives_corruptions():
    lines = shared_file("ntu/S001C001P001R001A001.skeleton").read_text().splitlines()
    numeric = [i for i, line in enumerate(lines) if len(line.split()) == 12]  # joint lines

    @FUZZ
    @given(st.data())
    def run(data):
        parsed = _read(lambda p: (s := read_skeleton_file(p), s.keypoints()), "S001C001P001R001A001.skeleton",
                       _mutate_lines(data, lines, numeric))  # fmt: skip
        if parsed is None:
            return
        sequence, keypoint = parsed
        assert keypoint.ndim == 4 and keypoint.shape[2:] == (25, 3) and np.isfinite(keypoint).all()
        assert all(np.isfinite(b.joints).all() for f in sequence.frames for b in f.bodies)

    run()


def test_bvh_reader_survives_corruptions():
    lines = shared_file("bvh/cmu_01_01.bvh").read_text().splitlines()
    motion = lines.index("MOTION")
    head = lines[: motion + 1] + ["Frames: 20", lines[motion + 2]]  # the hierarchy and 20 frames: faster
    lines = head + lines[motion + 3 : motion + 23]
    offsets = [i for i, line in enumerate(lines) if "OFFSET" in line]
    numeric = offsets[::4] + list(range(len(head) - 2, len(lines)))  # some offsets, the header, the frames

    @FUZZ
    @given(st.data())
    def run(data):
        bvh = _read(load_bvh, "clip.bvh", _mutate_lines(data, lines, numeric))
        if bvh is None:
            return
        assert bvh.values.shape == (bvh.num_frames, sum(len(c) for c in bvh.channels)) and bvh.num_frames >= 1
        assert np.isfinite(bvh.values).all() and np.isfinite(bvh.offsets).all() and 1 <= bvh.fps <= 1000

    run()


def _kinetics_clip(frames: int = 6, people: int = 2) -> dict:
    rng = np.random.default_rng(0)
    data = [{"frame_index": t + 1,
             "skeleton": [{"pose": rng.random(2 * KINETICS_JOINTS).round(3).tolist(),
                           "score": rng.random(KINETICS_JOINTS).round(3).tolist()} for _ in range(people)]}
            for t in range(frames)]  # fmt: skip
    return {"data": data, "label": "abseiling", "label_index": 0}


_JSON_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-(10**30), 10**30), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=5), st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=40),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)  # fmt: skip


def _replace_somewhere(data: st.DataObject, node):
    """Replace (or delete) one value at a random place in a JSON structure, in place."""
    while True:
        keys = list(node) if isinstance(node, dict) else list(range(len(node)))
        if not keys:
            return
        key = data.draw(st.sampled_from(keys))
        child = node[key]
        if isinstance(child, dict | list) and child and data.draw(st.booleans()):
            node = child
            continue
        if isinstance(node, dict) and data.draw(st.booleans()):
            del node[key]
        else:
            node[key] = data.draw(_JSON_VALUES)
        return


def test_kinetics_reader_survives_corruptions():
    @FUZZ
    @given(st.data())
    def run(data):
        clip = _kinetics_clip()
        if data.draw(st.booleans()):  # a poison number in one pose or score
            rng = data.draw(st.randoms(use_true_random=False))
            person = rng.choice(rng.choice(clip["data"])["skeleton"])
            values = person[rng.choice(["pose", "score"])]
            values[rng.randrange(len(values))] = data.draw(st.sampled_from([NAN, INF, -INF, 1e39]))
        for _ in range(data.draw(st.integers(0, 2))):
            _replace_somewhere(data, clip)
        text = json.dumps(clip)
        if data.draw(st.booleans()):  # also damage the text itself, one number a line
            lines = text.replace(", ", "\n, ").splitlines()
            text = _mutate_lines(data, lines, list(range(len(lines))))
        parsed = _read(read_kinetics_clip, "clip.json", text)
        if parsed is None:
            return
        keypoint, score, label, name = parsed
        assert keypoint.shape[:3] == score.shape and keypoint.shape[2:] == (KINETICS_JOINTS, 2)
        assert np.isfinite(keypoint).all() and np.isfinite(score).all()
        assert isinstance(label, int) and label >= 0 and isinstance(name, str)

    run()


def test_humanml3d_reader_survives_corruptions():
    sample = np.load(shared_file("humanml3d/new_joint_vecs/012314.npy"))

    @FUZZ
    @given(st.data())
    def run(data):
        array = sample.astype(np.float64)
        kind = data.draw(st.sampled_from(["poison", "shape", "dtype", "truncate", "flip"]))
        if kind == "poison":
            flat = array.reshape(-1)
            for i in data.draw(st.lists(st.integers(0, flat.size - 1), min_size=1, max_size=4)):
                flat[i] = data.draw(st.sampled_from([np.nan, np.inf, -np.inf, 1e39, -1e300]))
        elif kind == "shape":
            array = array[: data.draw(st.integers(0, 5)), : data.draw(st.integers(0, FEATURE_DIM + 1))]
        elif kind == "dtype":
            array = array.astype(data.draw(st.sampled_from([np.int16, np.bool_, np.complex64, "U3"])))
        with tempfile.TemporaryDirectory() as folder:
            np.save(Path(folder) / "a.npy", array)
            raw = bytearray((Path(folder) / "a.npy").read_bytes())
        if kind == "truncate":
            raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
        elif kind == "flip":
            for _ in range(data.draw(st.integers(1, 4))):
                raw[data.draw(st.integers(0, 127))] = data.draw(st.integers(0, 255))
        features = _read(read_features, "000001.npy", bytes(raw))
        if features is None:
            return
        assert features.dtype == np.float32 and features.ndim == 2 and features.shape[1] == FEATURE_DIM
        assert len(features) >= 1 and np.isfinite(features).all()

    run()
