"""benchmarks/gpu.py and benchmarks/bench_training.py: their plans (``--dry-run``) and, on the CPU at a
tiny size, the parity and timing code the GPU run uses; the compiled propagation's code path traced."""

from __future__ import annotations

from types import ModuleType

import pytest
import torch

import semattnet
from semattnet.inference.backends.compiled_propagation import compiled_propagation, traced_propagation
from semattnet.models.refinement import refine
from tests._helpers import random_inputs
from tests.benchmarks._scripts import load_script as _load


@pytest.fixture(scope="module")
def gpu() -> ModuleType:
    return _load("gpu")


@pytest.fixture(scope="module")
def model() -> torch.nn.Module:
    torch.manual_seed(0)
    return semattnet.build_model("semattnet", width=0.125, iterations=2).eval()


def test_gpu_dry_run_checks_its_plan(gpu: ModuleType, capsys) -> None:  # type: ignore[no-untyped-def]
    assert gpu.main(["--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "plan ok" in out and '"step": "training"' in out and '"backend": "tensorrt"' in out
    steps = gpu.plan(torch.device("cuda"), 8)
    with pytest.raises(AssertionError):
        gpu.check_plan([s for s in steps if s.get("backend") != "eager" or s["step"] != "parity"], 450)
    with pytest.raises(AssertionError):
        gpu.check_plan(steps, 900)  # over the 8 minutes


@pytest.mark.slow  # the whole script's CPU path: ~35 s on 2 cores; the dry run checks its plan by default
def test_gpu_parity_and_latency_on_cpu(gpu: ModuleType, model: torch.nn.Module) -> None:
    cpu = torch.device("cpu")
    x = gpu.frame(1, (64, 96), cpu)
    with torch.inference_mode():
        ref = model(**x).refined_depth
    runnable = [n for n, _, _ in gpu.BACKENDS if gpu.available(n, cpu) is None]
    assert runnable == ["eager", "bf16"]  # what the CPU can run without torch.compile
    for name, _, tol in gpu.BACKENDS:
        if name in runnable:
            fn = gpu.build(name, model, cpu, (64, 96))
            assert gpu.parity(fn, ref, x) <= tol, name
    t = gpu.latency(lambda: gpu.build("eager", model, cpu, (64, 96))(**x), cpu, 2)
    assert t["median_s"] > 0 and t["p95_s"] >= t["median_s"]


def test_compiled_propagation_code_path_matches_the_reference(model: torch.nn.Module) -> None:
    with torch.inference_mode():
        _, heads = model.forward_network(**random_inputs(b=1, h=32, w=32))
    naive = refine(heads, 1, "naive")
    traced = traced_propagation(heads, 1)  # the recorded form that torch.compile compiles
    for a, b in zip(traced, naive, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)
    assert compiled_propagation() is compiled_propagation()  # one compiled function per mode


@pytest.mark.slow  # Inductor on 2 CPU cores: minutes
def test_compiled_propagation_on_cpu(model: torch.nn.Module) -> None:
    with torch.inference_mode():
        _, heads = model.forward_network(**random_inputs(b=1, h=64, w=96))
        got = compiled_propagation()(heads, 2)
    for a, b in zip(got, refine(heads, 2, "naive"), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_cuda_backends_match_eager(gpu: ModuleType, model: torch.nn.Module) -> None:
    dev = torch.device("cuda")
    net = model.to(dev)
    x = gpu.frame(1, (64, 96), dev)
    with torch.inference_mode():
        ref = net(**x).refined_depth
    for name, _, tol in gpu.BACKENDS:
        if gpu.available(name, dev) is None:
            assert gpu.parity(gpu.build(name, net, dev, (64, 96)), ref, x) <= tol, name


def test_bench_training_dry_run_and_one_child(capsys) -> None:  # type: ignore[no-untyped-def]
    bench = _load("bench_training")
    assert bench.main(["--dry-run", "--batches", "1,2", "--rounds", "2"]) == 0
    out = capsys.readouterr().out
    assert "12 processes" in out and "recipe-reconstruction@1, ours@1, ours+ckpt@1, recipe-reconstruction@1" in out
    with pytest.raises(AssertionError):
        bench.check_plan([("ours", 1), ("recipe-reconstruction", 1), ("ours+ckpt", 1)], bench.VARIANTS, (1,))
    r = bench.child("ours+ckpt", 1, (32, 64), 0.125, "cpu", steps=1, warmup=0)
    assert r["seconds"] > 0 and r["peak_mib"] > r["before_mib"] > 0 and r["params"] > 10**5
    fake = [
        {
            "variant": "recipe-reconstruction",
            "batch": b,
            "seconds": 2.0 * b,
            "peak_mib": 1000.0 + 500 * b,
            "before_mib": 100.0,
            "params": 10**6,
        }
        for b in (1, 2)
    ]
    table = "\n".join(bench.summarise(fake, ("recipe-reconstruction",)))
    # 500 MiB per sample, 1000 MiB fixed: 24 GB = 22888 MiB -> 43 samples
    assert "0.49" in table and "43" in table and "measured" in table
    pair = [
        {"variant": v, "batch": 2, "seconds": t, "peak_mib": m, "before_mib": 100.0, "params": 10**6}
        for v, t, m in (("ours", 10.0, 4000.0), ("ours+ckpt", 13.0, 1800.0))
    ]
    table = "\n".join(bench.summarise(pair, ("ours", "ours+ckpt")))
    assert "ours+ckpt / ours batch 2: step time 1.30x, peak memory 0.45x" in " ".join(table.split())
    assert bench.main(["--dry-run", "--variants", "ours,ours+ckpt", "--batches", "4"]) == 0
    assert "2 processes" in capsys.readouterr().out
