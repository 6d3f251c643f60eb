"""The uncertainty in the outputs: its 16-bit encoding, the ``--max-uncertainty`` limit, the sinks and the viewer."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from semattnet._errors import InputError
from semattnet.data.frames import Frame
from semattnet.data.io import read_depth
from semattnet.inference.completer import Completion
from semattnet.inference.sinks import (
    OutputSettings,
    PlySink,
    UncertaintyNpySink,
    UncertaintyPngSink,
    default_sinks,
    output_files,
    predict_frame,
)
from semattnet.inference.uncertainty import UncertaintyLimit, encode_uncertainty

pytestmark = pytest.mark.filterwarnings("ignore:.*hole:UserWarning")  # the frame's holes, on purpose

H, W = 12, 20
K = np.array([[20.0, 0, 9.5], [0, 20.0, 5.5], [0, 0, 1]])


def _prediction(uncertainty: bool = True, **frame_fields: object):
    rng = np.random.default_rng(3)
    depth = rng.uniform(2, 40, (H, W)).astype(np.float32)
    depth[0, :4] = 0  # holes
    unc = rng.uniform(0, 3, (H, W)).astype(np.float32)
    unc[1, 0], unc[1, 1], unc[1, 2] = 0.0, 1e-4, 1e6  # none, below one step, above the range
    sparse = np.where(rng.random((H, W)) < 0.2, depth, 0).astype(np.float32)
    frame = Frame("f0", rng.integers(0, 256, (H, W, 3), dtype=np.uint8), sparse, K=K, **frame_fields)  # type: ignore[arg-type]
    return predict_frame(frame, Completion(depth, uncertainty=unc if uncertainty else None))


def test_encoding_is_metres_times_256_with_0_for_none() -> None:
    pred = _prediction()
    u, d = pred.completion.uncertainty, pred.stored
    assert u is not None and pred.uncertainty_png is not None and pred.uncertainty_png.dtype == np.uint16
    want = np.where(d > 0, np.clip(np.round(u.astype(np.float64) * 256), 1, 65535), 0)
    np.testing.assert_array_equal(pred.uncertainty_png, want)
    assert (pred.uncertainty_png[0, :4] == 0).all()  # no depth, no uncertainty
    assert pred.uncertainty_png[1, 0] == pred.uncertainty_png[1, 1] == 1  # 0 keeps meaning "none"
    assert pred.uncertainty_png[1, 2] == 65535
    stored = pred.uncertainty_stored
    assert stored is not None and np.allclose(stored, pred.uncertainty_png / 256.0)
    np.testing.assert_array_equal(encode_uncertainty(stored, d), pred.uncertainty_png)  # a fixed point
    assert pred.uncertainty is not None and pred.uncertainty[1, 2] == 1e6  # the .npy: unclamped


def test_png_and_npy_sinks_round_trip(tmp_path: Path) -> None:
    pred = _prediction()
    sinks = default_sinks(OutputSettings(npy=True, uncertainty=True))
    assert output_files(["f0"], sinks) == [
        "f0.png",
        "f0_color.png",
        "f0.npy",
        "uncertainty/f0.png",
        "uncertainty/f0.npy",
    ]
    for sink in sinks:
        sink.write(tmp_path, pred)
    back = read_depth(tmp_path / "uncertainty" / "f0.png")
    np.testing.assert_array_equal(np.round(back * 256).astype(np.uint16), pred.uncertainty_png)
    npy = np.load(tmp_path / "uncertainty" / "f0.npy")
    assert npy.dtype == np.float32 and npy.shape == (H, W)
    u = pred.completion.uncertainty
    assert u is not None
    ok = (pred.stored > 0) & (u < 1e5)
    np.testing.assert_array_equal(npy[ok], u[ok])
    assert (npy[pred.stored == 0] == 0).all()
    assert (
        default_sinks(OutputSettings(uncertainty=False, npy=True))[-1].__class__.__name__ == "NpySink"
    )  # no uncertainty asked


def test_sinks_without_uncertainty_say_so(tmp_path: Path) -> None:
    pred = _prediction(uncertainty=False)
    for sink in (UncertaintyPngSink(), UncertaintyNpySink()):
        with pytest.raises(InputError, match="f0: --uncertainty: the method gives no per-pixel uncertainty"):
            sink.write(tmp_path, pred)
    with pytest.raises(InputError, match="--max-uncertainty: the method gives no"):
        pred.cloud(80.0, 0, UncertaintyLimit(1.0))


@pytest.mark.parametrize("text", ["0.5", "5%"])
def test_cloud_keeps_exactly_the_pixels_under_the_limit(text: str, tmp_path: Path) -> None:
    from plyfile import PlyData

    from semattnet.geometry import depth_to_points

    pred = _prediction()
    limit = UncertaintyLimit.parse(text)
    u, d = pred.uncertainty_png / 256.0, pred.stored  # type: ignore[operator]
    keep = (d > 0) & ((u <= 0.05 * d) if limit.relative else (u <= 0.5))
    assert 0 < keep.sum() < (d > 0).sum()
    cloud = pred.cloud(80.0, 0, limit)
    assert len(cloud.xyz) == int(keep.sum())
    np.testing.assert_array_equal(cloud.xyz, depth_to_points(d, K, mask=keep).xyz)
    PlySink(max_uncertainty=limit).write(tmp_path, pred)
    ply = PlyData.read(str(tmp_path / "f0.ply"))["vertex"]
    assert ply.count == int(keep.sum())
    np.testing.assert_array_equal(np.column_stack([ply["x"], ply["y"], ply["z"]]), cloud.xyz)
    assert len(pred.cloud(80.0, 0)) == int((d > 0).sum())  # no limit: every pixel with depth


def test_an_empty_cloud_names_its_cause_not_a_file(tmp_path: Path) -> None:
    pred = _prediction()
    with pytest.raises(InputError) as info:  # every uncertainty is at least 1/256 m: nothing is kept
        PlySink(max_uncertainty=UncertaintyLimit(0.001)).write(tmp_path, pred)
    assert str(info.value).startswith("f0: --max-uncertainty 0.001: no pixel's uncertainty is within it")
    with pytest.raises(InputError, match="f0: no completed pixel within 1 m below the top 0 rows"):
        PlySink(max_depth=1.0).write(tmp_path, pred)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("text", "value", "relative"), [("0.5", 0.5, False), (" 2 ", 2.0, False), ("5%", 0.05, True), ("250%", 2.5, True)]
)
def test_parse(text: str, value: float, relative: bool) -> None:
    limit = UncertaintyLimit.parse(text)
    assert (limit.value, limit.relative) == (pytest.approx(value), relative)
    assert UncertaintyLimit.parse(str(limit)) == limit


@pytest.mark.parametrize("text", ["", "abc", "0", "-1", "0%", "300", "1500%", "nan", "inf", "5%%", "%"])
def test_parse_refuses_in_one_line(text: str) -> None:
    with pytest.raises(InputError) as info:
        UncertaintyLimit.parse(text)
    assert "expected metres in (0, 255] (e.g. 0.5) or a percentage of the depth in (0, 1000%]" in str(info.value)
    assert "\n" not in str(info.value)
    with pytest.raises(InputError):
        UncertaintyLimit(math.nan)


def test_viewer_has_an_uncertainty_layer(tmp_path: Path) -> None:
    pytest.importorskip("plotly")
    from semattnet.viz.viewer import ViewerFrame, write_viewer

    pred = _prediction()
    frame = ViewerFrame(
        "f0", pred.frame.rgb, pred.frame.sparse, {"m": pred.stored}, K=K, uncertainty=pred.uncertainty_stored
    )
    plain = ViewerFrame("f1", pred.frame.rgb, pred.frame.sparse, {"m": pred.stored}, K=K)
    write_viewer(tmp_path, [frame, plain])

    def data(i: int) -> dict:
        text = (tmp_path / "viewer" / f"{i:03d}.js").read_text()
        return json.loads(text[text.index(",") + 1 : text.rindex(")")])

    layers = [layer["label"] for layer in data(0)["layers"] if layer["key"] == "uncertainty"]
    assert len(layers) == 1 and layers[0].startswith("m: uncertainty (0 to ")
    assert any(v["key"] == "uncertainty" and v["unit"] == "m" for v in data(0)["values"])
    assert not any(layer["key"] == "uncertainty" for layer in data(1)["layers"])


def test_birds_eye_view_of_the_panel_uses_the_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The panel's bird's-eye view is drawn from the limited cloud; its depth tiles stay dense."""
    import semattnet.viz.panels as panels
    from semattnet.geometry import RigCalibration
    from semattnet.inference.sinks import PanelSink

    seen: dict[str, object] = {}

    def bev(cloud, points, calib, shape, max_depth):  # type: ignore[no-untyped-def]
        seen["points"] = len(cloud.xyz)
        return np.zeros((*shape, 3), np.uint8)

    def panel(path, rgb, semantic, sparse, outputs, gt=None, extra=()):  # type: ignore[no-untyped-def]
        seen["depth"] = outputs["refined_depth"]

    monkeypatch.setattr(panels, "birds_eye_tile", bev)
    monkeypatch.setattr(panels, "branch_panel", panel)
    pred = _prediction(points=np.zeros((5, 4), np.float32), calib=RigCalibration(K, np.eye(4), (W, H), "cam"))
    limit = UncertaintyLimit(0.5)
    PanelSink(max_uncertainty=limit).write(tmp_path, pred)
    keep = pred.keep(limit)
    assert keep is not None and seen["points"] == keep.sum() < (pred.stored > 0).sum()
    np.testing.assert_array_equal(seen["depth"], pred.stored)


def test_predict_report_shows_the_uncertainty(tmp_path: Path) -> None:
    pytest.importorskip("plotly")
    from click.testing import CliRunner

    from semattnet.cli import main
    from semattnet.data.io import write_depth, write_image

    pred = _prediction()
    (tmp_path / "rgb").mkdir()
    (tmp_path / "sparse").mkdir()
    write_image(tmp_path / "rgb" / "a.png", pred.frame.rgb)
    write_depth(tmp_path / "sparse" / "a.png", pred.frame.sparse)
    out = tmp_path / "out"
    args = ["--rgb", tmp_path / "rgb", "--sparse", tmp_path / "sparse", "--method", "classical", "--out", out]
    res = CliRunner().invoke(main, ["predict", *map(str, args), "--uncertainty", "--report"])
    assert res.exit_code == 0, res.output
    assert (out / "uncertainty" / "a.png").is_file()
    assert '"key":"uncertainty"' in (out / "viewer" / "000.js").read_text()
