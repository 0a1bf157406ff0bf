"""A backbone setting is given in one place (issue 44, item 2): a field a task derives (EMM's ``context_dim``
from ``network.context_dim``, every task's skeleton and channels, the dancer's ``causal``, recognition's
skeleton and channels from the data) is refused when the recipe's backbone sets it otherwise, instead of being
silently overwritten; the same value, or the field's default, is accepted."""

from __future__ import annotations

import pytest

from skeleton_mamba import MixerConfig, SkeletonMambaConfig
from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.egodance.model import EMM, EMMConfig
from skeleton_mamba.tasks.qean.model import QEANConfig, SkeletonMambaMotionEncoder
from skeleton_mamba.tasks.recognition.module import ActionRecognitionModule
from skeleton_mamba.tasks.stream.model import StreamDancer
from skeleton_mamba.tasks.text2motion.model import TextToMotionDenoiser
from skeleton_mamba.tasks.training.backbone_config import derived_backbone
from skeleton_mamba.tasks.training.cli import main as sm_main

TINY = dict(dim=16, depth=1, heads=2, mlp_dim=32, mixer=MixerConfig(d_state=8, headdim=8, chunk_size=16))
NETWORK = EMMConfig(context_dim=16, use_vision=False, heads=2, transformer_ff=32)


def test_a_derived_field_set_otherwise_is_refused_in_one_line():
    given = SkeletonMambaConfig(**TINY, context_dim=64, out_channels=3)
    with pytest.raises(InputError) as caught:
        derived_backbone(given, "EMM", skeleton="smpl24", out_channels=10, context_dim=32)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(
        "backbone.out_channels = 3 but EMM sets 10; backbone.context_dim = 64 but EMM sets 32: a backbone "
        "setting is given in one place; remove it from the backbone"
    )


def test_the_same_value_or_the_default_is_taken():
    same = derived_backbone(SkeletonMambaConfig(**TINY, context_dim=32), "EMM", context_dim=32)
    default = derived_backbone(SkeletonMambaConfig(**TINY), "EMM", skeleton="ntu25", context_dim=32)
    assert (same.context_dim, default.context_dim, default.skeleton) == (32, 32, "ntu25")
    assert derived_backbone(None, "EMM", context_dim=8).context_dim == 8


def test_emm_refuses_a_second_context_width_and_keeps_its_own():
    with pytest.raises(InputError, match=r"backbone.context_dim = 64 but EMM sets 16"):
        EMM(SkeletonMambaConfig(**TINY, context_dim=64), NETWORK)
    assert EMM(SkeletonMambaConfig(**TINY, context_dim=16), NETWORK).backbone.config.context_dim == 16
    assert EMM(SkeletonMambaConfig(**TINY), NETWORK).backbone.config.context_dim == 16


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda b: StreamDancer(b, music_dim=4), "in_channels"),
        (lambda b: TextToMotionDenoiser(b, text_dim=8), "in_channels"),
        (lambda b: SkeletonMambaMotionEncoder(QEANConfig(hidden=16, heads=2), b), "in_channels"),
        (lambda b: ActionRecognitionModule(b, num_classes=3, skeleton="ntu25", in_channels=3), "in_channels"),
    ],
    ids=["stream", "text2motion", "qean", "recognition"],
)
def test_every_task_refuses_channels_given_twice(build, field):
    with pytest.raises(InputError, match=rf"backbone\.{field} = 99 but "):
        build(SkeletonMambaConfig(**TINY, in_channels=99))


def test_the_dancer_takes_a_causal_backbone_as_its_own():
    dancer = StreamDancer(SkeletonMambaConfig(**TINY, causal=True), music_dim=4)
    assert dancer.backbone.config.causal is True  # the same value as the dancer's: taken


def test_sm_fit_refuses_the_recipe_setting_context_dim_twice(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = sm_main(
        ["fit", "--recipe", "egodance_demo.yaml", "--model.init_args.backbone.context_dim", "64", "--quiet"]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert (
        err.startswith("sm fit: error: backbone.context_dim = 64 but EMM sets 32: ") and err.count("\n") == 1
    )
