"""Generated, class-separable skeleton sequences in the PYSKL annotation format (no download).

Used by the ``recognition_synthetic.yaml`` demo recipe, the tests and the loader benchmark. Class
``c`` shifts and swings the joints of tokenizer group ``(c + 1) mod G`` (right arm, left arm, right
leg, ...) along coordinate axis ``c mod D`` (a sinusoid with a random phase per sample), on top of a
fixed random rest pose, a random global offset and Gaussian noise.
"""

from __future__ import annotations

import numpy as np

from skeleton_mamba.skeletons import get_skeleton

__all__ = ["make_synthetic_annotations"]


def make_synthetic_annotations(
    num_classes: int = 3,
    train_per_class: int = 16,
    val_per_class: int = 8,
    num_frames: int = 32,
    skeleton: str = "ntu25",
    num_bodies: int = 1,
    amplitude: float = 1.0,
    displacement: float = 1.0,
    noise: float = 0.02,
    seed: int = 0,
    train_split: str = "xsub_train",
    val_split: str = "xsub_val",
) -> dict:
    """A PYSKL-format annotation dict: ``{"split": {...}, "annotations": [...]}``.

    3D keypoints (M, T, V, 3) for ``ntu25``; 2D keypoints (M, T, V, 2) in [0, 1] plus
    ``keypoint_score`` (M, T, V) for ``openpose18`` (as in Kinetics-skeleton), float32.

    Args:
        num_classes: K classes, labels 0..K-1.
        train_per_class: samples per class in ``train_split``.
        val_per_class: samples per class in ``val_split``.
        num_frames: T, frames per sample (``total_frames``).
        skeleton: ``ntu25`` (3D) or ``openpose18`` (2D with scores).
        num_bodies: M bodies per sample (all move the same way, each with its own offset).
        amplitude: swing amplitude (metres for 3D, image fraction / 3 for 2D).
        displacement: static shift of the moving group, as a fraction of ``amplitude`` (0: motion only).
        noise: standard deviation of the per-joint Gaussian noise.
        seed: random seed (the output is a pure function of the arguments).
        train_split: name of the training split.
        val_split: name of the validation split.
    """
    skel = get_skeleton(skeleton)
    two_d = skel.name == "openpose18"
    dims = 2 if two_d else 3
    rng = np.random.default_rng(seed)
    rest = rng.normal(scale=0.3, size=(skel.num_joints, dims))
    t = np.linspace(0.0, 2.0 * np.pi, num_frames, dtype=np.float64)
    annotations, split = [], {train_split: [], val_split: []}
    for name, per_class in ((train_split, train_per_class), (val_split, val_per_class)):
        for label in range(num_classes):
            group = skel.groups[(label + 1) % skel.num_groups]
            axis = label % dims
            for i in range(per_class):
                phase = rng.uniform(0.0, 2.0 * np.pi)
                motion = np.zeros((num_frames, skel.num_joints, dims))
                motion[:, list(group), axis] = amplitude * (displacement + np.sin(t + phase))[:, None]
                offset = rng.normal(scale=0.5, size=(num_bodies, 1, 1, dims))
                keypoint = (
                    rest
                    + motion
                    + offset
                    + rng.normal(scale=noise, size=(num_bodies, num_frames, *rest.shape))
                )
                frame_dir = f"{name}_{label:03d}_{i:04d}"
                ann = {"frame_dir": frame_dir, "label": label, "total_frames": num_frames}
                if two_d:
                    ann["keypoint"] = (0.5 + keypoint / 3.0).astype(np.float32)
                    ann["keypoint_score"] = np.ones(keypoint.shape[:-1], dtype=np.float32)
                    ann["img_shape"], ann["original_shape"] = (1, 1), (256, 340)  # [0, 1] coordinates
                else:
                    ann["keypoint"] = keypoint.astype(np.float32)
                annotations.append(ann)
                split[name].append(frame_dir)
    return {"split": split, "annotations": annotations}
