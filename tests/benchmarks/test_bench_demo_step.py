"""benchmarks/bench_demo_step.py builds the demo recipe's module and times a real training step."""

import json

import torch

from tests.helpers.repo import load_script


def _load_benchmark():
    return load_script("benchmarks/bench_demo_step.py")


def test_demo_step_benchmark_trains_the_recipes_module(capsys):
    bench = _load_benchmark()
    module, data = bench.build_module()
    assert module.model.vision_encoder.image_size == data["image_size"] == 32
    assert module.model.frame_condition is not None  # the recipe's network, not EMMConfig's defaults
    batch = bench.demo_batch(data)
    assert batch["frames"].shape == (4, 150, 3, 32, 32) and batch["frames"].is_contiguous()
    before = [p.detach().clone() for p in module.parameters()]
    optimizer = torch.optim.AdamW(module.parameters(), lr=1e-3)
    optimizer.zero_grad()
    loss = module.training_step(batch, 0)
    loss.backward()
    optimizer.step()
    assert torch.isfinite(loss)
    assert any(not torch.equal(a, b) for a, b in zip(before, module.parameters(), strict=True))
    assert bench.main(["--repeats", "1", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["train_step_ms"] > 0 and abs(result["steps_per_s"] - 1e3 / result["train_step_ms"]) < 0.01
    assert result["vision_encoder_ms"] > 0 and result["head_estimator_ms"] > 0
    assert result["page_faults_per_step"] >= 0 and result["system_ms_per_step"] >= 0
    assert isinstance(result["training_allocator"], bool)
