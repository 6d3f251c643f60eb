"""The interactive viewer (semattnet.viz.viewer) and ``predict --report``, rendered by headless Chromium."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from semattnet.cli import main
from semattnet.data.io import read_depth
from semattnet.synthetic import make_frame
from semattnet.viz.viewer import ViewerFrame, cloud_points, cloud_stride, parse_intrinsics, write_viewer
from tests.apps._browser import hover_pixel, open_page, wait_ready

H, W = 64, 192


@pytest.mark.parametrize(("h", "w", "cap"), [(64, 192, 12000), (96, 320, 12000), (352, 1216, 12000), (5, 7, 1)])
def test_cloud_stride_is_the_smallest_step_under_the_cap(h: int, w: int, cap: int) -> None:
    s = cloud_stride(h, w, cap)
    assert -(-h // s) * -(-w // s) <= cap
    assert s == 1 or -(-h // (s - 1)) * -(-w // (s - 1)) > cap


def test_parse_intrinsics() -> None:
    K = parse_intrinsics("700,710,600.5,170")
    assert K.tolist() == [[700, 0, 600.5], [0, 710, 170], [0, 0, 1]]
    assert parse_intrinsics("kitti")[0, 0] == pytest.approx(721.5377)
    with pytest.raises(ValueError):
        parse_intrinsics("1,2,3")


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """A viewer folder with two frames: a "model" (ground-truth depth plus made-up intermediates) and a worse method."""
    fr = make_frame(H, W, seed=3, shadow=True)
    outputs = {
        k: fr.depth * f
        for k, f in (
            ("color_depth", 1.1),
            ("semantic_depth", 0.95),
            ("guided_depth", 1.0),
            ("fused_depth", 1.02),
            ("refined_depth", 1.0),
        )
    }
    outputs |= {
        k: np.full((H, W), w, np.float32)
        for k, w in (("color_conf", 0.2), ("semantic_conf", 0.3), ("guided_conf", 0.5))
    }
    depths = {"classical": fr.depth * 0.9, "semattnet": fr.depth}
    frames = [
        ViewerFrame(f"scene{i}", fr.rgb, fr.sparse, depths, fr.semantic, fr.gt, outputs, "semattnet", fr.K)
        for i in range(2)
    ]
    out = tmp_path_factory.mktemp("viewer")
    return write_viewer(out, frames, {"semattnet": "SemAttNet (test)"}), fr


def test_viewer_folder(synthetic) -> None:  # type: ignore[no-untyped-def]
    page, _ = synthetic
    out = page.parent
    assert sorted(p.name for p in (out / "viewer").iterdir()) == ["000.js", "001.js"]
    assert (out / "plotly.min.js").stat().st_size > 1_000_000
    assert "cdn" not in page.read_text().lower()
    assert sum(p.stat().st_size for p in (out / "viewer").iterdir()) < 2_000_000


def _pixel_with(depth: np.ndarray, other: np.ndarray) -> tuple[int, int]:
    """A pixel (u, v) where both maps have a depth."""
    v, u = np.argwhere((depth > 0) & (other > 0))[len(np.argwhere((depth > 0) & (other > 0))) // 2]
    return int(u), int(v)


def test_viewer_in_chromium(synthetic, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    page_path, fr = synthetic
    with open_page(page_path) as (page, errors):
        wait_ready(page)
        u, v = _pixel_with(fr.sparse, fr.gt)
        values = hover_pixel(page, u, v)
        assert values["lidar"] == pytest.approx(fr.sparse[v, u], abs=0.01)
        assert values["gt"] == pytest.approx(fr.gt[v, u], abs=0.01)
        assert values["depth_classical"] == pytest.approx(0.9 * fr.depth[v, u], abs=0.01)
        assert values["out_color_depth"] == pytest.approx(1.1 * fr.depth[v, u], abs=0.01)
        assert values["out_guided_conf"] == pytest.approx(0.5, abs=0.01)
        # The 3D view: the predicted cloud on the pixel grid, and every LiDAR point.
        counts = page.evaluate("document.getElementById('cloud').data.map((t) => t.x.length)")
        assert counts == [len(cloud_points(fr.depth, fr.K, cloud_stride(H, W))), int((fr.sparse > 0).sum())]
        # A layer toggle changes the picture.
        before = page.locator("#view").screenshot()
        page.check("#layers input[value='rgb']")
        assert page.get_attribute("#view", "data-layer") == "rgb"
        after = page.locator("#view").screenshot()
        assert _pixels(before, tmp_path / "a.png").shape == _pixels(after, tmp_path / "b.png").shape
        assert np.abs(_pixels(before, tmp_path / "a.png") - _pixels(after, tmp_path / "b.png")).mean() > 10
        # The second frame loads on demand and keeps the chosen layer.
        page.select_option("#frame", "1")
        wait_ready(page, 1)
        assert page.get_attribute("#view", "data-layer") == "rgb"
        page.screenshot(path=str(page_path.parent / "viewer.png"), full_page=True)
        assert page.get_attribute("body", "data-error") is None
    assert errors == []


def _pixels(png: bytes, path: Path) -> np.ndarray:
    path.write_bytes(png)
    return np.asarray(Image.open(path).convert("RGB")).astype(np.int16)


@pytest.fixture(scope="module")
def predicted(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """``semattnet predict --method classical --report`` on one synthetic frame, with and without --K."""
    fr = make_frame(H, W, seed=5)
    src = tmp_path_factory.mktemp("inputs")
    Image.fromarray(fr.rgb).save(src / "f.png")
    (src / "sparse").mkdir()
    Image.fromarray(np.round(fr.sparse * 256).astype(np.uint16)).save(src / "sparse" / "f.png")
    outs = {}
    for tag, extra in (
        ("k", ["--K", ",".join(str(fr.K[i, j]) for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)))]),
        ("nok", []),
    ):
        outs[tag] = tmp_path_factory.mktemp(f"pred_{tag}")
        args = [
            "predict",
            "--method",
            "classical",
            "--rgb",
            str(src / "f.png"),
            "--sparse",
            str(src / "sparse" / "f.png"),
            "--out",
            str(outs[tag]),
            "--report",
            *extra,
        ]
        args += ["--npy"] if tag == "k" else []
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 0, result.output
        assert "viewer:" in result.output
    return outs, fr


def test_predict_report_in_chromium(predicted) -> None:  # type: ignore[no-untyped-def]
    outs, fr = predicted
    pred_npy = np.load(outs["k"] / "f.npy")
    pred_png = read_depth(outs["nok"] / "f.png")
    u, v = _pixel_with(pred_npy, fr.sparse)
    for tag, pred in (("k", pred_npy), ("nok", pred_png)):
        with open_page(outs[tag] / "viewer.html") as (page, errors):
            wait_ready(page)
            values = hover_pixel(page, u, v)
            assert set(values) == {"lidar", "depth_prediction"}  # no ground truth, no intermediates
            assert values["depth_prediction"] == pytest.approx(pred[v, u], abs=0.01)
            assert values["lidar"] == pytest.approx(fr.sparse[v, u], abs=0.01)
            if tag == "k":
                counts = page.evaluate("document.getElementById('cloud').data.map((t) => t.x.length)")
                assert counts[0] == len(cloud_points(pred_npy, fr.K, cloud_stride(H, W)))
            else:
                assert page.locator("#cloud").is_hidden()
                assert "no camera intrinsics" in page.inner_text("#cloud-note")
        assert errors == []


def test_predict_report_refuses_bad_intrinsics(tmp_path: Path) -> None:
    args = [
        "predict",
        "--method",
        "classical",
        "--rgb",
        str(tmp_path),
        "--sparse",
        str(tmp_path),
        "--out",
        str(tmp_path / "o"),
        "--report",
        "--K",
        "1,2",
    ]
    result = CliRunner().invoke(main, args)
    assert result.exit_code != 0 and "--K" in result.output
