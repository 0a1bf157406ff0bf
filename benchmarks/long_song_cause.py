"""Where the EgoMusic demo's long-song error comes from, measured on a trained ``egodance_demo.yaml`` run.

For every held-out window the demo scores, the window sampled alone (as the demo samples it) against the mean
pose's MPJPE on the same window; for the demo's 60 s song, each 5 s segment of the joined dance and of the
segments sampled alone against the mean pose; and how well the head-trajectory estimator sees the head's
yaw in the song's egocentric video: its yaw over each sampling window against the truth's (after removing
the slow turn with a 31-frame moving average: the swing of the dance), and its error at the frame where the
next window starts (what a heading anchor would need), the song's windows sampled alone by where they start
(every 5 s, as the training windows start in their dances, or half a window later), and the joined song with
and without in-painting the overlaps. Writes its entry (``--as before`` for a run
trained without the head's turns as a condition, ``--as after`` for the recipe as it is) into
``benchmarks/long_song_cause.json`` (``--out``), from which ``demo_seeds.py tables`` renders the tutorial's
table.

    sm fit --recipe egodance_demo.yaml --model.init_args.network.heading_condition false \
        --model.init_args.inpaint_overlaps true                                          # before
    python benchmarks/long_song_cause.py --as before --run runs/egodance_demo/version_0
    sm fit --recipe egodance_demo.yaml                                                      # after
    python benchmarks/long_song_cause.py --as after --run runs/egodance_demo/version_1
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch
from common import machine_info

from skeleton_mamba.tasks.egodance.data import data_module_from_hparams
from skeleton_mamba.tasks.egodance.head_estimator import estimate_window_trajectories
from skeleton_mamba.tasks.egodance.heading_frames import head_heading, head_rotation
from skeleton_mamba.tasks.egodance.long_demo import _segment_starts, _windows_alone, score_long_dance
from skeleton_mamba.tasks.egodance.long_form import LongForm
from skeleton_mamba.tasks.egodance.long_form_scores import segments
from skeleton_mamba.tasks.egodance.module import EgoDanceModule
from skeleton_mamba.tasks.egodance.representation import motion_joints
from skeleton_mamba.tasks.motion.metrics.pose_distance import mpjpe
from skeleton_mamba.tasks.training.checkpoints import load_module_and_checkpoint

OUT = Path(__file__).resolve().parent / "long_song_cause.json"


def _mpjpe(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(mpjpe(a.double(), b.double()))


def _swing(heading: torch.Tensor, width: int = 31) -> torch.Tensor:
    """(B, T) headings (radians) less their moving average over ``width`` frames."""
    padded = torch.nn.functional.pad(heading[:, None], (width // 2, width // 2), mode="replicate")
    return heading - torch.nn.functional.avg_pool1d(padded, width, 1)[:, 0]


def _wrap_deg(angle: torch.Tensor) -> torch.Tensor:
    return torch.rad2deg(torch.remainder(angle + torch.pi, 2 * torch.pi) - torch.pi)


@torch.no_grad()
def measure(run: Path, data_root: Path) -> dict:
    module, checkpoint = load_module_and_checkpoint(EgoDanceModule, str(run / "checkpoints" / "last.ckpt"))
    module.eval()
    data = data_module_from_hparams({**checkpoint["datamodule_hyper_parameters"], "root": str(data_root)})
    data.setup("fit")
    train = [motion_joints(item["motion"]) for item in data.datasets["train"].items]
    mean_pose = torch.cat([c.reshape(-1, 24, 3) for c in train]).mean(0)
    dataset = data.datasets["test"]
    windows = []
    for index in range(len(dataset)):
        item = dataset[index]
        batch = {k: v[None] for k, v in item.items() if torch.is_tensor(v)}
        truth = motion_joints(item["motion"])
        dance = motion_joints(module.sample(batch, index)[0])
        windows.append({"window": dataset.folders[index].name, "mpjpe_m": _mpjpe(dance, truth),
                        "mean_pose_mpjpe_m": _mpjpe(mean_pose.expand_as(truth), truth)})  # fmt: skip
    folder = sorted((data_root / "long_60s" / "ego" / "samples").iterdir())[0]
    tokens, inputs, scores = score_long_dance(module, folder, mean_pose)
    hp = module.hparams
    long_form = LongForm(hp.window, 75, bool(hp.canonicalize_init_head))
    starts = _segment_starts(len(inputs.music), long_form)
    truth_segments = segments(inputs.truth, starts, long_form.window, long_form.canonical)
    dance_segments = segments(tokens, starts, long_form.window, long_form.canonical)
    per_segment = [_mpjpe(motion_joints(a), motion_joints(b)) for a, b in zip(dance_segments, truth_segments)]
    mean_segment = [
        _mpjpe(mean_pose.expand(long_form.window, 24, 3), motion_joints(b)) for b in truth_segments
    ]
    # the head estimator's yaw over the windows that fit in the song (the segments)
    _, rotations = estimate_window_trajectories(
        module.head_estimator.eval(), inputs.video.head, starts, long_form.window
    )
    # the windows sampled alone, by where they start: every 5 s (as the training windows in their dances) or
    # half a window later
    alone = motion_joints(_windows_alone(module, inputs, long_form, starts))
    truth = motion_joints(truth_segments)
    even = [i for i, s in enumerate(starts) if (s // long_form.hop) % 2 == 0]
    odd = [i for i, s in enumerate(starts) if (s // long_form.hop) % 2 == 1]
    # the joined song with and without in-painting the overlaps ([EDGE]'s long form and the cross-fade alone)
    own = module.inpaint_overlaps
    joined = {
        own: scores["mpjpe_m"],
        not own: score_long_dance(module, folder, mean_pose, inpaint=not own)[2]["mpjpe_m"],
    }
    true_yaw = head_heading(head_rotation(truth_segments.double()))
    estimated_yaw = head_heading(rotations.double())
    true_swing, estimated_swing = _swing(true_yaw), _swing(estimated_yaw)
    at_next = _wrap_deg(estimated_yaw[:, long_form.hop] - true_yaw[:, long_form.hop]).abs()
    return {
        "machine": machine_info(),
        "run": "/".join(run.parts[-3:]),  # runs/egodance_demo/version_N
        "heading_condition": bool(module.model.config.heading_condition),
        "held_out_windows": windows,
        "long_song": {
            "sample": folder.name,
            "mpjpe_m": scores["mpjpe_m"],
            "windows_alone_mpjpe_m": scores["windows_alone_mpjpe_m"],
            "even_windows_alone_mpjpe_m": _mpjpe(alone[even], truth[even]),
            "odd_windows_alone_mpjpe_m": _mpjpe(alone[odd], truth[odd]),
            "inpainted_mpjpe_m": joined[True],
            "cross_faded_mpjpe_m": joined[False],
            "inpaint_overlaps": own,
            "mean_pose_mpjpe_m": scores["mean_pose_mpjpe_m"],
            "per_segment_mpjpe_m": per_segment,
            "per_segment_mean_pose_mpjpe_m": mean_segment,
        },
        "head_estimator_yaw": {
            "true_swing_std_deg": float(torch.rad2deg(true_swing).std()),
            "estimated_swing_std_deg": float(torch.rad2deg(estimated_swing).std()),
            "swing_correlation": float(
                (true_swing * estimated_swing).sum() / (true_swing.norm() * estimated_swing.norm())
            ),
            "error_at_next_window_deg": {
                "min": float(at_next.min()),
                "max": float(at_next.max()),
                "mean": float(at_next.mean()),
            },  # fmt: skip
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, required=True, help="runs/egodance_demo/version_N of a demo run")
    parser.add_argument(
        "--data", type=Path, default=Path("runs/egodance_demo/data"), help="the demo's data root"
    )
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument(
        "--as",
        dest="label",
        choices=("before", "after"),
        default="after",
        help="the entry the run's figures replace: before (a run trained with "
        "--model.init_args.network.heading_condition false --model.init_args.inpaint_overlaps true, the "
        "recipe before this change) or after (the recipe as it is)",
    )
    args = parser.parse_args()
    result = measure(args.run, args.data)
    expected = args.label == "after"
    if result["heading_condition"] != expected:
        parser.error(
            f"--as {args.label}: {args.run} was trained with heading_condition {result['heading_condition']}"
        )
    both = json.loads(args.out.read_text(encoding="utf-8")) if args.out.exists() else {}
    both = {k: v for k, v in both.items() if k in ("before", "after")}
    both[args.label] = result
    tmp = args.out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(both, indent=2) + "\n", encoding="utf-8")
    tmp.replace(args.out)
    print(json.dumps(result["long_song"] | result["head_estimator_yaw"], indent=2))


if __name__ == "__main__":
    main()
