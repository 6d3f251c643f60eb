"""benchmarks/bench_authors.py and bench_training.py's ``authors-code`` variant, at tiny sizes, against a stand-in for
the authors' checkout (tests/benchmarks/_fake_authors.py: their interface around our model, never their code)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from types import ModuleType

import pytest
import torch

import semattnet
from tests.benchmarks._fake_authors import WIDTH, write_fake_authors
from tests.benchmarks._scripts import load_script


@pytest.fixture(scope="module")
def src(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_fake_authors(tmp_path_factory.mktemp("authors") / "SemAttNet")


@pytest.fixture(scope="module")
def authors_code() -> ModuleType:
    return load_script("authors_code")


def test_their_code_is_imported_in_isolation(authors_code: ModuleType, src: Path, tmp_path: Path) -> None:
    module = authors_code.load_authors_module(src)
    assert hasattr(module, "A_CSPN_plus_plus") and module.WIDTH == WIDTH  # their `from basic import *` worked
    assert not {"model", "basic", "attention"} & set(sys.modules)  # their names left nothing behind
    assert str(src) not in sys.path
    with pytest.raises(SystemExit, match="no model.py"):
        authors_code.load_authors_module(tmp_path)


@pytest.mark.skipif(torch.cuda.is_available(), reason="the shim is for machines without CUDA")
def test_cpu_shim_makes_cuda_calls_no_ops(authors_code: ModuleType) -> None:
    t, m = torch.zeros(1), torch.nn.Linear(1, 1)
    with authors_code.cpu_shim():
        assert t.cuda() is t and m.cuda() is m
    with pytest.raises((AssertionError, RuntimeError)):  # restored: no CUDA here
        t.cuda()


def test_the_same_weights_in_their_model_and_ours(authors_code: ModuleType, src: Path) -> None:
    theirs = authors_code.build_authors_model(src, (32, 64))
    ours = authors_code.fill_weights(semattnet.build_model("semattnet", width=WIDTH))
    a, b = theirs.net.state_dict(), ours.state_dict()
    assert list(a) == list(b) and all(torch.equal(a[k], b[k]) for k in a)
    bn = next(v for k, v in b.items() if k.endswith("running_var"))
    assert 0.75 <= float(bn.min()) and float(bn.max()) <= 1.25  # the rule, not PyTorch's init


def test_bench_authors_times_theirs_and_ours_with_parity(src: Path, tmp_path: Path) -> None:
    bench = load_script("bench_authors")
    out = tmp_path / "r.json"
    assert (
        bench.main(
            [
                "--authors-src",
                str(src),
                "--size",
                "32x64",
                "--rounds",
                "1",
                "--engines",
                "torch",
                "--width",
                str(WIDTH),
                "--no-memory",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    r = json.loads(out.read_text())
    speed = r["speed"]
    assert set(speed["seconds"]) == {"authors", "ours-torch"} and set(speed["speedup"]) == {"ours-torch"}
    assert speed["speedup"]["ours-torch"] == pytest.approx(speed["seconds"]["authors"] / speed["seconds"]["ours-torch"])
    assert speed["max_rel_error"]["ours-torch"] <= 1e-4  # the same weights loaded into ours
    assert r["cpu"] and r["size"] == [32, 64] and "memory" not in r
    m = bench.memory_child("authors", src, (32, 64), WIDTH)
    assert m["variant"] == "authors" and m["inference_peak_mib"] > 0 and m["process_peak_mib"] > 0
    lines = bench.table(r | {"memory": {"peaks": {"authors": m}, "ratio": {}}})
    assert lines[0].startswith("CPU: ") and lines[2].startswith("authors") and lines[3].startswith("ours-torch")


@pytest.mark.slow  # OpenVINO's export and one child process per variant: about a minute on 2 cores
def test_bench_authors_whole_run_with_memory(src: Path, tmp_path: Path) -> None:
    bench = load_script("bench_authors")
    out = tmp_path / "r.json"
    assert (
        bench.main(
            [
                "--authors-src",
                str(src),
                "--size",
                "32x64",
                "--rounds",
                "1",
                "--width",
                str(WIDTH),
                "--no-int8",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    r = json.loads(out.read_text())
    assert set(r["memory"]["peaks"]) == {"authors", "ours-torch", "ours-openvino"}
    assert set(r["memory"]["ratio"]) == {"ours-torch", "ours-openvino"}
    assert max(r["speed"]["max_rel_error"].values()) <= 1e-4


def test_bench_training_authors_code_variant(src: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bench = load_script("bench_training")
    assert bench.main(["--dry-run", "--authors-src", str(src)]) == 0
    assert "authors-code@1, recipe-reconstruction@1, ours@1, ours+ckpt@1" in capsys.readouterr().out
    with pytest.raises(SystemExit):  # the variant without the checkout
        bench.main(["--dry-run", "--variants", "authors-code,ours"])
    r = bench.child("authors-code", 1, (32, 64), WIDTH, "cpu", steps=1, warmup=0, authors_src=src)
    assert r["variant"] == "authors-code" and r["seconds"] > 0 and r["peak_mib"] > r["before_mib"] > 0
    assert r["params"] == sum(p.numel() for p in semattnet.build_model("semattnet", width=WIDTH).parameters())
    fake = [
        {"variant": v, "batch": 1, "seconds": s, "peak_mib": m, "before_mib": 100.0, "params": 10**6}
        for v, s, m in (("authors-code", 4.0, 2000.0), ("ours", 2.0, 1000.0))
    ]
    table = " ".join("\n".join(bench.summarise(fake, ("authors-code", "ours"))).split())
    assert "ratios to authors-code" in table and "ours 1 2.00 2.00 0.98 0.50" in table


@pytest.mark.slow  # ~6 s: a training step under the profiler
def test_bench_training_profile_times_the_convolutions_of_a_step() -> None:
    bench = load_script("bench_training")
    r = bench.child("ours", 1, (32, 64), WIDTH, "cpu", steps=1, warmup=0, profile=True)
    assert 0 < r["conv_seconds"] < r["profiled_seconds"]  # the step has convolutions and more


def test_bench_training_profile_bounds_the_speed_up_by_the_convolutions() -> None:
    """``--profile``: the convolutions' self seconds of one more step, and reference step time / them."""
    bench = load_script("bench_training")
    runs = (("authors-code", 8.0, 5.0), ("ours", 6.0, 4.0))
    fake = [
        {
            "variant": v,
            "batch": 1,
            "seconds": s,
            "peak_mib": 1000.0,
            "before_mib": 100.0,
            "params": 10**6,
            "conv_seconds": c,
            "profiled_seconds": s,
        }
        for v, s, c in runs
    ]
    table = "\n".join(bench.summarise(fake, ("authors-code", "ours")))
    row = next(line for line in table.splitlines() if line.startswith("ours ") and "%" in line)
    assert row.split() == ["ours", "1", "4.00", "2.00", "66.7%", "2.00x"]  # 8 s / 4 s of convolutions
