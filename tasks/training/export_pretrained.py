"""``sm export-pretrained --ckpt CKPT --out DIR``: a Lightning checkpoint as a Hugging Face folder.

The folder is the task network's ``from_pretrained`` folder (:mod:`skeleton_mamba.pretrained.mixin`):
``config.json``, ``model.safetensors`` (the network the module infers with: the EMA copy when it keeps one,
with its data statistics), ``README.md`` (the model card: task, skeleton, sizes, the module's
hyper-parameters, the data module's, test metrics from the run's ``metrics.csv`` when a test ran,
citations), and ``module.safetensors`` with the module's other tensors, so that ``sm dance`` /
``sm generate`` / ``sm stream`` / ``sm predict`` rebuild the module from the folder
(:mod:`.pretrained`). The checkpoint is read through the one checker
(:mod:`~skeleton_mamba.tasks.training.checkpoints`); its hyper-parameters name the module class
(``_class_path``, as LightningCLI stores it; ``--module`` for a checkpoint without one).

Example::

    sm export-pretrained --ckpt runs/egodance_demo/version_0/checkpoints/last.ckpt --out emm-demo/
    sm export-pretrained --ckpt last.ckpt --out emm-demo/ --push-to-hub my-org/emm-demo
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

from lightning.pytorch import LightningModule
from safetensors.torch import save

from skeleton_mamba.errors import CheckpointError, InputError
from skeleton_mamba.io.atomic import atomic_path
from skeleton_mamba.pretrained.mixin import (
    CARD_NAME,
    CONFIG_NAME,
    WEIGHTS_NAME,
    PretrainedMixin,
    push_folder_to_hub,
    read_pretrained_config,
)
from skeleton_mamba.tasks.motion.io.output_folder import claim_output_folder, writing_outputs
from skeleton_mamba.tasks.training.checkpoints import load_checkpoint, load_module_and_checkpoint
from skeleton_mamba.tasks.training.export_pretrained_args import build_parser
from skeleton_mamba.tasks.training.pretrained import MODULE_WEIGHTS_NAME, import_project_class, module_record

__all__ = ["export_pretrained", "main", "network_attribute", "test_metrics"]

# where task modules keep their network, in the order preferred (the EMA copy is what they sample with)
NETWORK_ATTRIBUTES = ("ema.module", "model", "denoiser")


def network_attribute(module) -> str:
    """The attribute path of ``module``'s pretrained network (:data:`NETWORK_ATTRIBUTES`, first found)."""
    for path in NETWORK_ATTRIBUTES:
        obj = module
        for name in path.split("."):
            obj = getattr(obj, name, None)
        if isinstance(obj, PretrainedMixin):
            return path
    raise CheckpointError(
        f"{type(module).__name__}: holds no network with save_pretrained ({NETWORK_ATTRIBUTES})"
    )


def test_metrics(checkpoint_path: Path) -> dict[str, float]:
    """The last logged value of each ``test*`` column of the run's ``metrics.csv`` (``RUN/checkpoints/x.ckpt``
    -> ``RUN/metrics.csv``); empty when there is none (no test ran)."""
    path = checkpoint_path.parent.parent / "metrics.csv"
    if not path.is_file():
        return {}
    metrics: dict[str, float] = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            for key, value in row.items():
                if key and key.startswith("test") and value not in (None, ""):
                    try:
                        number = float(value)
                    except ValueError:
                        continue
                    if math.isfinite(number):
                        metrics[key] = number
    return metrics


def export_pretrained(
    ckpt: str | Path,
    out: str | Path,
    module_class: str | None = None,
    recipe: str | None = None,
    overwrite: bool = False,
) -> Path:
    """Write the folder of the checkpoint ``ckpt`` into ``out``; returns ``out``.

    ``out`` must be missing, empty or this command's earlier export (its four files and nothing else), unless
    ``overwrite`` (:func:`~skeleton_mamba.tasks.motion.io.output_folder.claim_output_folder`).

    Raises:
        CheckpointError: as the checker, or a checkpoint that does not name its module class.
        InputError: ``out`` holds other files.
    """
    names = (CONFIG_NAME, WEIGHTS_NAME, CARD_NAME, MODULE_WEIGHTS_NAME)
    claim_output_folder(out, "sm export-pretrained", names, overwrite=overwrite)
    checkpoint = load_checkpoint(ckpt)
    hparams = checkpoint.get("hyper_parameters") or {}
    class_path = module_class or (hparams.get("_class_path") if isinstance(hparams, dict) else None)
    if not isinstance(class_path, str):
        raise CheckpointError(
            f"{ckpt}: its hyper-parameters name no module class (_class_path); pass --module"
        )
    cls = import_project_class(class_path, str(ckpt), LightningModule)
    module, checkpoint = load_module_and_checkpoint(cls, ckpt)
    attribute = network_attribute(module)
    record = module_record(module, checkpoint, attribute)
    state = module.state_dict()
    prefix = f"{attribute}."
    rest = {k: v.detach().cpu().contiguous() for k, v in state.items() if not k.startswith(prefix)}
    network = module.get_submodule(attribute)
    data = record["datamodule_hyper_parameters"]
    card = {
        "recipe": recipe,
        "module": record["class_path"],
        "hparams": record["hparams"],
        "data": data.get("_class_path") if isinstance(data, dict) else None,
        "data_hparams": data,
        "metrics": test_metrics(Path(ckpt)),
        "trained": {k: record[k] for k in ("epoch", "global_step") if k in record},
    }
    with writing_outputs(out, "sm export-pretrained", names, replaces=True) as folder:
        with atomic_path(folder / MODULE_WEIGHTS_NAME) as tmp:
            tmp.write_bytes(save(rest, metadata={"format": "pt", "module": record["class_path"]}))
        network.save_pretrained(folder, card_info=card, extra_config={"module": record})
    return folder


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``sm export-pretrained``; returns the exit code."""
    args = build_parser().parse_args(list(argv) if argv is not None else None)
    folder = export_pretrained(args.ckpt, args.out, args.module, args.recipe, args.overwrite)
    config = read_pretrained_config(folder)
    print(f"wrote {folder}/ ({config['class'].rsplit('.', 1)[-1]} of {config['module']['class_path']})")
    if args.push_to_hub:
        try:
            info = push_folder_to_hub(folder, args.push_to_hub, private=args.private or None)
        except OSError as err:  # no network, refused credentials
            raise InputError(f"{args.push_to_hub}: upload failed ({type(err).__name__}: {err})") from err
        print(f"uploaded to {getattr(info, 'commit_url', args.push_to_hub)}")
    return 0
