"""A SYNTHETIC demo set in the AIST++ layout (the live dancer's and QEAN's demos train on it, no download).

``<root>/motions/<name>.pkl`` (smpl_poses, smpl_trans, smpl_scaling at 60 fps, as AIST++ stores them),
``<root>/music/<music id>.wav``, ``<root>/splits/crossmodal_{train,val}.txt`` and ``SYNTHETIC.txt``: the
toolkit's beat-synchronised procedural dances (:mod:`.dance`) and drum tracks (:mod:`.music`), one music id
per dance, names ``g<genre>_sBM_cAll_d<k>_m<genre><i>_ch01``.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from skeleton_mamba.io.atomic import atomic_open
from skeleton_mamba.tasks.motion.formats.aistpp import music_id
from skeleton_mamba.tasks.motion.synthetic.dance import STYLES, synthesize_dance
from skeleton_mamba.tasks.motion.synthetic.music import synthesize_music, write_music

__all__ = ["LABEL", "write_synthetic_aistpp"]

LABEL = "SYNTHETIC demo data (procedural dances, synthesised drum tracks)"
GENRES = ("BR", "PO", "LO", "MH", "LH", "WA", "KR", "JS", "JB", "HO")
SCALING = 93.0  # AIST++ stores smpl_trans in units of smpl_scaling


def write_synthetic_aistpp(
    root: str | Path, count: int = 8, duration_s: float = 12.0, val_count: int = 2, seed: int = 0
) -> list[str]:
    """Write ``count`` SYNTHETIC dances + music in the AIST++ layout under ``root``; returns their names.

    The last ``val_count`` names go to ``splits/crossmodal_val.txt``, the others to ``crossmodal_train.txt``.
    """
    if not 0 <= val_count < count <= 10 * len(GENRES):
        raise ValueError(f"need 0 <= val_count < count <= {10 * len(GENRES)}, got {val_count}, {count}")
    root = Path(root)
    for folder in ("motions", "music", "splits"):
        (root / folder).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    styles = sorted(STYLES)
    names = []
    for k in range(count):
        genre, index = GENRES[k % len(GENRES)], k // len(GENRES)
        name = f"g{genre}_sBM_cAll_d{k:02d}_m{genre}{index}_ch01"
        bpm = float(rng.integers(90, 141))
        motion = synthesize_dance(bpm, duration_s, fps=60.0, style=styles[k % len(styles)], seed=seed + k)
        data = {
            "smpl_poses": motion.poses.reshape(-1, 72).astype(np.float32),
            "smpl_trans": (motion.root_position() * SCALING).astype(np.float32),
            "smpl_scaling": np.array([SCALING], dtype=np.float32),
        }
        with atomic_open(root / "motions" / f"{name}.pkl", "wb") as f:
            pickle.dump(data, f)
        write_music(
            root / "music" / f"{music_id(name)}.wav", synthesize_music(bpm, duration_s, seed=seed + k)
        )
        names.append(name)
    train, val = names[: count - val_count], names[count - val_count :]
    (root / "splits" / "crossmodal_train.txt").write_text("\n".join(train) + "\n", encoding="utf-8")
    (root / "splits" / "crossmodal_val.txt").write_text("\n".join(val) + "\n", encoding="utf-8")
    (root / "SYNTHETIC.txt").write_text(
        "SYNTHETIC demo data: procedural dances and synthesised drum tracks in the AIST++ layout.\n",
        encoding="utf-8",
    )
    return names
