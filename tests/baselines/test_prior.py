"""``--method prior``: a monocular depth model put on the sparse points' scale. The fit against hand-made
predictions (an exact affine inverse depth, a metric one off by a scale, outliers), then a tiny random Depth
Anything (transformers, saved with ``save_pretrained``; no weights can be downloaded here) through ``predict`` and
``evaluate``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet._errors import DataError
from semattnet.baselines.prior import PriorCompleter, fit_prior
from semattnet.cli import main
from semattnet.data.io import read_depth, write_depth, write_image


def _scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A (32, 64) depth field 2-40 m and 10 % of it as sparse points."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:32, 0:64]
    depth = (2.0 + 38.0 * (xx / 63.0) ** 1.5 + 0.1 * yy).astype(np.float64)
    sparse = np.where(rng.random(depth.shape) < 0.1, depth, 0).astype(np.float32)
    return depth, sparse


def test_a_relative_prediction_is_put_on_the_points_scale_despite_outliers() -> None:
    depth, sparse = _scene()
    s, t = 0.5, -0.02
    relative = (1.0 / depth - t) / s  # 1 / D = s r + t exactly
    ys, xs = np.nonzero(sparse)
    sparse[ys[:3], xs[:3]] = 80.0  # three returns seen through glass
    fitted = fit_prior(relative, sparse, relative=True)
    np.testing.assert_allclose(fitted, (s, t), rtol=1e-6, atol=1e-9)
    done = PriorCompleter(lambda rgb: relative, relative=True)(np.zeros((32, 64, 3), np.uint8), sparse)
    points = sparse[sparse > 0]
    inside = (depth >= points.min()) & (depth <= points.max())  # outside: clamped to the points' range
    np.testing.assert_allclose(done.depth[inside], depth[inside], rtol=1e-5)
    assert done.uncertainty is None and done.depth.dtype == np.float32


def test_a_metric_prediction_is_rescaled_only() -> None:
    depth, sparse = _scene(1)
    s, t = fit_prior(depth / 1.7, sparse, relative=False)  # a camera with another focal length
    assert t == 0.0 and s == pytest.approx(1.7, rel=1e-9)


def test_nothing_to_fit_is_one_line() -> None:
    depth, _ = _scene()
    one = np.zeros_like(depth, dtype=np.float32)
    one[3, 4] = 5.0
    with pytest.raises(DataError, match="at least 2 sparse points"):
        fit_prior(depth, one)
    _, sparse = _scene()
    with pytest.raises(DataError, match="same at every sparse point"):
        fit_prior(np.ones_like(depth), sparse)


@pytest.fixture(scope="module")
def tiny_prior(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A randomly initialised Depth Anything (a 4-layer Dinov2 of width 32) and its image processor."""
    transformers = pytest.importorskip("transformers")
    import torch

    torch.manual_seed(0)
    backbone = transformers.Dinov2Config(
        hidden_size=32,
        num_hidden_layers=4,
        num_attention_heads=2,
        intermediate_size=64,
        patch_size=14,
        image_size=56,
        out_features=["stage1", "stage2", "stage3", "stage4"],
        reshape_hidden_states=False,
    )
    config = transformers.DepthAnythingConfig(
        backbone_config=backbone,
        reassemble_hidden_size=32,
        neck_hidden_sizes=[8, 16, 32, 32],
        fusion_hidden_size=16,
        head_hidden_size=8,
        patch_size=14,
    )
    folder = tmp_path_factory.mktemp("prior")
    transformers.DepthAnythingForDepthEstimation(config).save_pretrained(folder)
    size = {"height": 56, "width": 112}
    processor = transformers.DPTImageProcessor(size=size, keep_aspect_ratio=False, ensure_multiple_of=14)
    processor.save_pretrained(folder)
    return folder


def test_predict_with_a_tiny_random_depth_anything(tiny_prior: Path, tmp_path: Path) -> None:
    _, sparse = _scene()
    for d in ("rgb", "sparse"):
        (tmp_path / d).mkdir()
    write_image(tmp_path / "rgb" / "f.png", np.random.default_rng(0).integers(0, 256, (32, 64, 3), dtype=np.uint8))
    write_depth(tmp_path / "sparse" / "f.png", sparse)
    args = ["predict", "--rgb", str(tmp_path / "rgb"), "--sparse", str(tmp_path / "sparse")]
    res = CliRunner().invoke(
        main, [*args, "--method", "prior", "--prior", f"hf:{tiny_prior}", "--out", str(tmp_path / "o")]
    )
    assert res.exit_code == 0, res.output
    out = read_depth(tmp_path / "o" / "f.png")
    points = sparse[sparse > 0]
    assert out.shape == (32, 64) and out.min() >= points.min() - 0.01 and out.max() <= points.max() + 0.01


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--prior", "hf:x/y"], "--prior only mean(s) something with --method prior"),
        (["--method", "prior"], "--method prior needs --prior"),
        (
            ["--method", "prior", "--prior", "hf:x/y", "--weights", "semattnet-rt-half-generalist"],
            "--method prior uses no model",
        ),
    ],
)
def test_prior_options_that_do_not_agree_are_usage_errors(tmp_path: Path, args: list[str], message: str) -> None:
    _, sparse = _scene()
    for d in ("rgb", "sparse"):
        (tmp_path / d).mkdir()
    write_image(tmp_path / "rgb" / "f.png", np.zeros((32, 64, 3), np.uint8))
    write_depth(tmp_path / "sparse" / "f.png", sparse)
    base = ["predict", "--rgb", str(tmp_path / "rgb"), "--sparse", str(tmp_path / "sparse")]
    res = CliRunner().invoke(main, [*base, *args, "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and message in res.output, res.output


def test_evaluate_scores_the_prior_on_nyu(tiny_prior: Path, tmp_path: Path) -> None:
    """The baselines are scored by evaluate like weights are (the NYU protocol's 500 points)."""
    pytest.importorskip("h5py")
    from tests.data._datasets import make_nyu

    root = make_nyu(tmp_path / "nyu", train=0, test=2)
    for method in (["--method", "prior", "--prior", f"hf:{tiny_prior}"], ["--method", "classical"]):
        out = tmp_path / method[1]
        res = CliRunner().invoke(
            main, ["evaluate", "--dataset", "nyuv2", "--data", str(root), "--workers", "0", *method, "--out", str(out)]
        )
        assert res.exit_code == 0, res.output
        assert (out / "metrics.json").is_file() and "rmse" in (out / "metrics.json").read_text().lower()
