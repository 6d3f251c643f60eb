"""benchmarks/bench_layers.py: the per-layer loss against the attainable rate, by hand and on a tiny graph."""

from __future__ import annotations

import pytest

from tests.benchmarks._scripts import load_script


def test_loss_is_time_minus_macs_at_the_best_large_layer_rate() -> None:
    bench = load_script("bench_layers")
    times = {
        ("a", "Convolution", "k"): 0.020,
        ("b", "Convolution", "k"): 0.010,
        ("c", "Reorder", "r"): 0.005,
        ("d", "Convolution", "k"): 0.004,
    }
    macs = {"a": 2_000_000_000, "b": 1_500_000_000, "d": 100_000_000}  # b: 150 GMAC/s, the best large one; d small
    r = bench.analyse(times, macs)
    assert r["attainable_gmac_s"] == pytest.approx(150.0)
    lost = {x["name"]: x["lost_ms"] for x in r["layers"]}
    assert lost["a"] == pytest.approx(20 - 2e9 / 150e9 * 1e3)  # 6.67 ms lost
    assert lost["b"] == pytest.approx(0.0, abs=1e-9) and lost["c"] == pytest.approx(5.0)
    assert lost["d"] == pytest.approx(4 - 0.1e9 / 150e9 * 1e3)
    assert [x["name"] for x in r["layers"]][:2] == ["a", "c"]  # the largest losses first
    assert r["floor_s"] == pytest.approx(3.6e9 / 150e9) and r["layers_s"] == pytest.approx(0.039)


def test_layer_macs_of_a_convolution_and_a_transposed_one() -> None:
    ov = pytest.importorskip("openvino")
    import openvino.opset13 as ops

    bench = load_script("bench_layers")
    x = ops.parameter([1, 8, 16, 16], name="x")
    conv = ops.convolution(x, ops.constant(bench.np.ones((4, 8, 3, 3), "f4")), [1, 1], [1, 1], [1, 1], [1, 1])
    up = ops.convolution_backprop_data(conv, ops.constant(bench.np.ones((4, 2, 5, 5), "f4")), [2, 2])
    conv.set_friendly_name("conv")
    up.set_friendly_name("up")
    macs = bench.layer_macs(ov.Model([up], [x]))
    assert macs == {"conv": 4 * 16 * 16 * 8 * 9, "up": 4 * 16 * 16 * 2 * 25}


@pytest.mark.slow
def test_the_script_on_a_tiny_model(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("openvino")
    bench = load_script("bench_layers")
    assert bench.main(["--size", "32x64", "--width", "0.25", "--runs", "2", "--top", "5"]) == 0
    out = capsys.readouterr().out
    assert "attainable" in out and "lost by type: " in out


def test_a_convolution_fused_with_its_bias_at_an_output_keeps_its_macs() -> None:
    """OpenVINO profiles a convolution + bias ending at a graph output under the output's name."""
    ov = pytest.importorskip("openvino")
    import openvino.opset13 as ops

    bench = load_script("bench_layers")
    x = ops.parameter([1, 8, 16, 16], name="x")
    conv = ops.convolution(x, ops.constant(bench.np.ones((4, 8, 3, 3), "f4")), [1, 1], [1, 1], [1, 1], [1, 1])
    biased = ops.add(conv, ops.constant(bench.np.ones((1, 4, 1, 1), "f4")))
    conv.set_friendly_name("conv")
    biased.set_friendly_name("conv/bias")
    biased.output(0).set_names({"refinement.heads"})
    model = ov.Model([biased], [x])
    assert bench.fused_names(model) == {"conv/bias": "conv", "refinement.heads": "conv"}
    assert bench.layer_macs(model) == {"conv": 4 * 16 * 16 * 8 * 9}  # counted once
