"""Property-based tests: image readers raise only DataError on any bytes; valid arrays round-trip;
metric invariants."""

from __future__ import annotations

import io
import tempfile
from pathlib import Path

import numpy as np
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from PIL import Image

from semattnet.data.io import DataError, read_depth, read_image, write_depth, write_image
from semattnet.evaluation.metrics import KittiMetrics

_SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _png(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(array).save(buf, format="PNG")
    return buf.getvalue()


_VALID = _png(np.arange(48, dtype=np.uint16).reshape(6, 8))


def _read_bytes(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "x.png"
        p.write_bytes(data)
        for reader in (read_depth, read_image):
            try:
                reader(p)
            except DataError:
                pass


@_SETTINGS
@given(st.binary(max_size=400))
def test_random_bytes_raise_only_data_error(data: bytes) -> None:
    _read_bytes(data)


@_SETTINGS
@given(st.lists(st.tuples(st.integers(0, len(_VALID) - 1), st.integers(0, 255)), min_size=1, max_size=8))
def test_mutated_pngs_raise_only_data_error(edits: list[tuple[int, int]]) -> None:
    data = bytearray(_VALID)
    for pos, value in edits:
        data[pos] = value
    _read_bytes(bytes(data))


@_SETTINGS
@given(arrays(np.uint16, st.tuples(st.integers(1, 12), st.integers(1, 12))))
def test_depth_round_trips_exactly(stored: np.ndarray) -> None:
    with tempfile.TemporaryDirectory() as d:
        path = write_depth(Path(d) / "d.png", stored.astype(np.float64) / 256.0)
        assert np.array_equal(np.round(read_depth(path) * 256.0).astype(np.uint16), stored)


@_SETTINGS
@given(arrays(np.uint8, st.tuples(st.integers(1, 12), st.integers(1, 12), st.just(3))))
def test_image_round_trips_exactly(image: np.ndarray) -> None:
    with tempfile.TemporaryDirectory() as d:
        assert np.array_equal(read_image(write_image(Path(d) / "i.png", image)), image)


def _metrics(pred: np.ndarray, gt: np.ndarray) -> dict[str, float]:
    m = KittiMetrics(fill_holes=False)
    m.update(torch.from_numpy(pred)[None, None], torch.from_numpy(gt)[None, None])
    return m.compute()


_depths = arrays(np.float32, (6, 7), elements=st.floats(1.0, 80.0, width=32))


@_SETTINGS
@given(_depths, _depths)
def test_rmse_at_least_mae_at_least_zero(pred: np.ndarray, gt: np.ndarray) -> None:
    r = _metrics(pred, gt)
    assert r["rmse_mm"] >= r["mae_mm"] * (1 - 1e-5) - 1e-3 and r["mae_mm"] >= 0
    assert r["irmse_per_km"] >= r["imae_per_km"] * (1 - 1e-5) - 1e-3 and r["imae_per_km"] >= 0


@_SETTINGS
@given(_depths)
def test_perfect_prediction_scores_zero(gt: np.ndarray) -> None:
    r = _metrics(gt.copy(), gt)
    assert r["rmse_mm"] == 0 and r["mae_mm"] == 0 and r["irmse_per_km"] == 0


@_SETTINGS
@given(_depths, _depths, st.sampled_from([0.5, 2.0, 4.0]))
def test_scaling_both_scales_rmse_and_mae(pred: np.ndarray, gt: np.ndarray, k: float) -> None:
    a, b = _metrics(pred, gt), _metrics(pred * k, gt * k)
    assert np.isclose(b["rmse_mm"], k * a["rmse_mm"], rtol=1e-3, atol=1e-2)
    assert np.isclose(b["mae_mm"], k * a["mae_mm"], rtol=1e-3, atol=1e-2)
