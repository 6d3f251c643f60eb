"""The synthetic scene generator and the `synth` / `data check` commands."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import DEPTH_SCALE
from semattnet.geometry import depth_to_points, project_points
from semattnet.synthetic.layout import CAM_HEIGHT
from semattnet.synthetic.materials import CLASS_IDS as _ID
from semattnet.synthetic.scenes import CITYSCAPES_PALETTE, MATERIALS, SCENE_STYLES, make_frame


@pytest.fixture(scope="module", params=[(352, 1216, 0), (352, 1216, 1), (96, 320, 2)])
def frame(request):  # type: ignore[no-untyped-def]
    h, w, seed = request.param
    return make_frame(h, w, seed=seed)


def test_statistics_are_kitti_like(frame) -> None:  # type: ignore[no-untyped-def]
    assert 0.03 < (frame.sparse > 0).mean() < 0.07  # ~5 % LiDAR
    assert 0.15 <= (frame.gt > 0).mean() <= 0.20  # ~16 % accumulated ground truth
    for d in (frame.sparse, frame.gt):
        v = d[d > 0]
        assert v.min() >= 1.0 and v.max() <= 80.0
        assert np.all(np.round(v * 256) == v * 256)  # representable in KITTI's uint16 encoding


def test_semantic_colours_are_palette_colours(frame) -> None:  # type: ignore[no-untyped-def]
    colours = {tuple(c) for c in np.unique(frame.semantic.reshape(-1, 3), axis=0)}
    assert colours <= set(CITYSCAPES_PALETTE.values())
    assert {CITYSCAPES_PALETTE[c] for c in ("road", "sky", "building")} <= colours


def test_sparse_agrees_with_exact_depth(frame) -> None:  # type: ignore[no-untyped-def]
    v = frame.sparse > 0
    rel = np.abs(frame.sparse[v] - frame.depth[v]) / frame.depth[v]
    # Sub-pixel position on slanted surfaces, 2 cm noise; the LiDAR's offset from the camera
    # makes a few points see past foreground edges, as in KITTI.
    assert np.mean(rel < 0.03) > 0.97
    gt = frame.gt > 0
    np.testing.assert_allclose(frame.gt[gt], frame.depth[gt], atol=1 / 512 + 1e-6)


def test_deterministic_and_shadow_only_changes_colour() -> None:
    a, b = make_frame(64, 128, seed=5, shadow=False), make_frame(64, 128, seed=5, shadow=False)
    for k in ("rgb", "semantic", "sparse", "gt", "depth"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    s = make_frame(64, 128, seed=5, shadow=True)
    np.testing.assert_array_equal(s.depth, a.depth)
    np.testing.assert_array_equal(s.semantic, a.semantic)
    assert s.rgb.mean() < a.rgb.mean() - 1  # a band of the scene is darker
    assert not np.array_equal(make_frame(64, 128, seed=6).depth, a.depth)


def _digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:16]


# The default style must keep drawing the same numbers in the same order (rgb, labels, sparse and gt in
# KITTI's 1/256 m steps). Re-pinned with the pixel-convention fix (issue 22): camera rays now go through
# pixel centres at integer coordinates and the LiDAR's points are binned by geometry.project_points
# (column floor(u + 0.5)), no longer through u + 0.5 and floor(u); every draw of the generator is
# unchanged (same meta, same LiDAR counts), the images and depths move by half a pixel.
_PINNED = {
    (64, 128, 3): ("034bcad2882b174b", "fa12ae70bbbd0962", "6af5b210e2d28a2a", "f9a366bace802251", 114064.112, True),
    (96, 320, 7): ("6ec46733573572c2", "38b65fa0e7f0bcfb", "0a8ea1c2e429d26d", "0f78160cf2cd4bb5", 615771.047, False),
}


# The realistic style in the source domain (what the shipped reference checkpoints were trained on), pinned when
# the domains (the rig and the look) were added: the default domain must keep drawing exactly these frames.
_PINNED_REALISTIC = {
    (64, 128, 3): ("9e2f0c5238eeb892", "11c2a05dd9aa1aa6", "9ace9695fe265d39", "0ab2785234a34263", 114279.154, False),
    (96, 320, 7): ("c2299d5861008ec4", "4681ac06a84ebf1e", "a976372375fd0b8e", "841de39344b3ebbc", 616202.952, True),
}


@pytest.mark.parametrize(
    ("style", "key"), [("ideal", k) for k in _PINNED] + [("realistic", k) for k in _PINNED_REALISTIC]
)
def test_default_domain_is_unchanged(style: str, key: tuple[int, int, int]) -> None:
    h, w, seed = key
    f = make_frame(h, w, seed=seed, style=style)
    rgb, labels, sparse, gt, depth_sum, shadowed = (_PINNED if style == "ideal" else _PINNED_REALISTIC)[key]
    assert _digest(f.rgb) == rgb
    assert _digest(f.labels.astype(np.uint8)) == labels
    assert _digest(np.round(f.sparse * 256).astype(np.uint16)) == sparse
    assert _digest(np.round(f.gt * 256).astype(np.uint16)) == gt
    assert f.depth.astype(np.float64).sum() == pytest.approx(depth_sum, abs=0.01)
    assert f.shadowed is shadowed


@pytest.mark.parametrize("style", SCENE_STYLES)
def test_sparse_map_is_geometry_projection_of_the_lidar_points(style: str) -> None:
    """One pixel convention: geometry.project_points of the frame's own LiDAR points is its sparse map."""
    f = make_frame(96, 320, seed=11, style=style)
    assert f.lidar_points is not None and f.T_cam_lidar is not None
    assert f.lidar_points.shape[1] == 3 and len(f.lidar_points) > 500
    depth = project_points(f.lidar_points, f.K, f.T_cam_lidar, (320, 96))
    np.testing.assert_array_equal(np.round(depth * DEPTH_SCALE) / DEPTH_SCALE, f.sparse)
    # The LiDAR frame has KITTI's Velodyne axes: x forward, z up (the sensor is 1.73 m above the road).
    assert np.median(f.lidar_points[:, 0]) > 3 and np.percentile(f.lidar_points[:, 2], 5) < -1.5


def test_camera_rays_go_through_integer_pixel_centres() -> None:
    """Back-projecting the exact depth at integer (u, v) (geometry's convention) lands road pixels on the road
    plane, to float32 precision; rays through u + 0.5 would miss it by half a pixel (~1 cm at 20 m)."""
    f = make_frame(96, 320, seed=2, shadow=False)
    road = (f.labels == _ID["road"]) & (f.depth > 10)
    cloud = depth_to_points(f.depth, f.K, mask=road)
    assert len(cloud) > 200
    np.testing.assert_allclose(cloud.xyz[:, 1], CAM_HEIGHT, atol=2e-5 * cloud.xyz[:, 2].max())


def test_synth_and_check_commands(tmp_path: Path) -> None:
    runner = CliRunner()
    out = tmp_path / "syn"
    r = runner.invoke(
        main,
        [
            "synth",
            "--out",
            str(out),
            "--frames",
            "4",
            "--size",
            "64x128",
            "--seed",
            "1",
            "--eval-frames",
            "2",
            "--workers",
            "2",
        ],
    )
    assert r.exit_code == 0, r.output
    manifest = json.loads((out / "scenes.json").read_text())
    assert manifest["counts"] == {"train": 4, "val": 2, "val_select": 2, "test": 2}
    assert manifest["style"] == "ideal"
    assert [f["shadowed"] for f in manifest["frames"] if f["split"] == "train"] == [False, True, False, True]
    again = runner.invoke(main, ["synth", "--out", str(out), "--frames", "1", "--size", "64x128"])
    assert again.exit_code != 0 and "not empty" in again.output
    check = runner.invoke(main, ["data", "check", str(out)])
    assert check.exit_code == 0, check.output
    assert "val_select" in check.output and "test" in check.output
    victim = next((out / "data_depth_annotated").rglob("*.png"))
    victim.unlink()
    broken = out / "data_depth_selection/val_selection_cropped/semantic"
    bad = sorted(broken.glob("*.png"))[0]
    bad.write_bytes(b"\x89PNG broken")
    check = runner.invoke(main, ["data", "check", str(out)])
    assert check.exit_code == 1
    assert str(victim) in check.output and "not a readable PNG" in check.output


def test_style_reaches_the_tree_and_the_manifest(tmp_path: Path) -> None:
    from semattnet.data.io import read_depth
    from semattnet.data.kitti import layout
    from semattnet.synthetic.tree import SYNTH_DATE, scene_seed, write_synthetic_kitti

    manifest = write_synthetic_kitti(
        tmp_path / "t", frames=2, size=(64, 128), seed=3, eval_frames=1, workers=1, style="realistic"
    )
    assert manifest["style"] == json.loads((tmp_path / "t" / "scenes.json").read_text())["style"] == "realistic"
    first = next(e for e in manifest["frames"] if e["split"] == "train" and e["index"] == 0)
    expected = make_frame(64, 128, seed=scene_seed(3, "train", 0), shadow=False, style="realistic").sparse
    drive = f"{SYNTH_DATE}_drive_0000_sync"
    written = layout.velodyne_path(tmp_path / "t", "train", drive, "02", "0000000000")
    np.testing.assert_array_equal(read_depth(written), expected)
    assert not np.array_equal(expected, make_frame(64, 128, seed=first["seed"], shadow=False).sparse)
    with pytest.raises(ValueError, match="scene style"):
        write_synthetic_kitti(tmp_path / "u", frames=1, size=(64, 128), style="nope")
    r = CliRunner().invoke(
        main,
        [
            "synth",
            "--out",
            str(tmp_path / "c"),
            "--frames",
            "2",
            "--size",
            "48x96",
            "--eval-frames",
            "2",
            "--workers",
            "1",
            "--style",
            "realistic",
        ],
    )
    assert r.exit_code == 0, r.output
    assert json.loads((tmp_path / "c" / "scenes.json").read_text())["style"] == "realistic"
    bad = CliRunner().invoke(main, ["synth", "--out", str(tmp_path / "d"), "--style", "photoreal"])
    assert bad.exit_code != 0 and "photoreal" in bad.output


def test_worker_count_does_not_change_the_data(tmp_path: Path) -> None:
    from semattnet.synthetic.tree import write_synthetic_kitti

    write_synthetic_kitti(tmp_path / "a", frames=3, size=(64, 128), seed=4, eval_frames=1, workers=1)
    write_synthetic_kitti(tmp_path / "b", frames=3, size=(64, 128), seed=4, eval_frames=1, workers=2)
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*.png"))
    assert len(files) == 3 * 4 + 1 * 4 + 1 * 4 + 1 * 3  # train, val, val_select (4 PNGs a frame), test (3)
    for f in files:
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f


# --- the "realistic" style ---------------------------------------------------------------------------------

_SEEDS = range(8)


@pytest.fixture(scope="module")
def realistic() -> list:  # type: ignore[type-arg]
    return [make_frame(352, 1216, seed=s, shadow=False, style="realistic") for s in _SEEDS]


@pytest.fixture(scope="module")
def ideal() -> list:  # type: ignore[type-arg]
    return [make_frame(352, 1216, seed=s, shadow=False) for s in _SEEDS]


def _return_rate(frames: list, mask) -> float:  # type: ignore[no-untyped-def,type-arg]
    """Share of the pixels ``mask(frame)`` selects that carry a LiDAR point, pooled over ``frames``."""
    hits = sum(int((mask(f) & (f.sparse > 0)).sum()) for f in frames)
    return hits / max(1, sum(int(mask(f).sum()) for f in frames))


def _cars(f, material: str):  # type: ignore[no-untyped-def]
    """Car pixels of one material between 5 and 30 m."""
    return (f.labels == _ID["car"]) & (f.material == MATERIALS.index(material)) & (f.depth > 5) & (f.depth < 30)


def test_realistic_is_deterministic_and_the_style_is_checked() -> None:
    a, b = make_frame(96, 320, seed=5, style="realistic"), make_frame(96, 320, seed=5, style="realistic")
    for k in ("rgb", "semantic", "sparse", "gt", "depth", "labels", "material", "paint"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    assert a.meta == b.meta and a.meta["style"] == "realistic"
    assert not np.array_equal(a.rgb, make_frame(96, 320, seed=5).rgb)
    assert not np.array_equal(a.sparse, make_frame(96, 320, seed=6, style="realistic").sparse)
    assert SCENE_STYLES[0] == "ideal" and make_frame(64, 128, seed=1).meta["style"] == "ideal"
    with pytest.raises(ValueError, match="scene style"):
        make_frame(64, 128, style="photoreal")


def test_realistic_keeps_kitti_statistics_and_exact_targets(realistic) -> None:  # type: ignore[no-untyped-def]
    for f in realistic:
        assert 0.03 < (f.sparse > 0).mean() < 0.06
        assert 0.15 <= (f.gt > 0).mean() <= 0.20
        gt = f.gt > 0
        np.testing.assert_allclose(f.gt[gt], f.depth[gt], atol=1 / 512 + 1e-6)  # glass is a surface for the gt
        assert {tuple(c) for c in np.unique(f.semantic.reshape(-1, 3), axis=0)} <= set(CITYSCAPES_PALETTE.values())
        lidar = f.meta["lidar"]
        assert lidar["returns"] < lidar["first_surface_hits"] <= lidar["rays"]


def test_dark_paint_returns_few_points(realistic) -> None:  # type: ignore[no-untyped-def]
    assert sum(f.meta["cars"]["dark"] for f in realistic) >= 3
    assert sum(f.meta["lidar"]["dropped_dark"] for f in realistic) > 0
    dark, matte = (
        _return_rate(realistic, lambda f: _cars(f, "dark")),
        _return_rate(realistic, lambda f: _cars(f, "matte")),
    )
    assert sum(int(_cars(f, "dark").sum()) for f in realistic) > 2000  # enough pixels to compare
    assert dark < 0.4 * matte, (dark, matte)


def test_glass_and_gloss_give_wrong_or_no_returns(realistic) -> None:  # type: ignore[no-untyped-def]
    behind = 0
    for f in realistic:
        glass = (f.labels == _ID["car"]) & (f.material == MATERIALS.index("glass")) & (f.sparse > 0)
        behind += int((glass & (f.sparse > f.depth + 0.5)).sum())
    assert behind > 200  # the beams passed through the windows and came back from behind the car
    assert sum(f.meta["lidar"]["wrong_glossy"] for f in realistic) > 0
    glossy = sum(int(((f.material == 2) & (f.sparse > f.depth + 0.5)).sum()) for f in realistic)
    assert glossy > 0  # mirrored beams: range too long
    windows = _return_rate(realistic, lambda f: (f.labels == _ID["building"]) & (f.material == 3))
    walls = _return_rate(realistic, lambda f: (f.labels == _ID["building"]) & (f.material == 0))
    assert windows < 0.3 * walls, (windows, walls)


def test_far_road_thins_out(realistic, ideal) -> None:  # type: ignore[no-untyped-def]
    def ratio(frames: list) -> float:  # type: ignore[type-arg]
        road = lambda f, lo, hi: (f.labels == _ID["road"]) & (f.depth >= lo) & (f.depth < hi)  # noqa: E731
        return _return_rate(frames, lambda f: road(f, 30, 80)) / _return_rate(frames, lambda f: road(f, 0, 15))

    assert ratio(realistic) < 0.7 * ratio(ideal), (ratio(realistic), ratio(ideal))


def test_paint_changes_colour_not_depth(realistic, ideal) -> None:  # type: ignore[no-untyped-def]
    assert sum(f.meta["posters"] for f in realistic) > 0
    strong = 0
    for f in realistic:
        rgb, d, paint = f.rgb.astype(float), f.depth.astype(float), f.paint
        pair = paint[:, 1:] & paint[:, :-1]  # neighbours both painted (a poster or a marking)
        edge = pair & (np.abs(rgb[:, 1:] - rgb[:, :-1]).mean(-1) > 60)
        strong += int(edge.sum())
        assert np.all(np.abs(d[:, 1:] - d[:, :-1])[edge] < 0.02 * d[:, 1:][edge])  # flat under the paint
    assert strong > 500

    def bright_road(frames: list) -> float:  # type: ignore[type-arg]
        shares = []
        for f in frames:
            grey = f.rgb.astype(float).mean(-1)[f.labels == _ID["road"]]
            shares.append(np.mean(grey > 1.8 * np.median(grey)))
        return float(np.mean(shares))

    assert bright_road(realistic) > 2 * bright_road(ideal)  # markings beyond the centre line


def _hidden_edges(f) -> int:  # type: ignore[no-untyped-def]
    """Neighbour pixel pairs car or pole | wall (no glass, no dark paint), > 2 m apart in depth, with
    the same colour (within 8 %, noise is 6 %) and not dark (where every colour looks alike)."""
    matte = f.material == MATERIALS.index("matte")
    fg = ((f.labels == _ID["car"]) | (f.labels == _ID["pole"])) & matte
    bld, rgb, d = (f.labels == _ID["building"]) & matte, f.rgb.astype(float), f.depth
    pair = (fg[:, 1:] & bld[:, :-1]) | (bld[:, 1:] & fg[:, :-1])
    lum = rgb.mean(-1)
    same = np.abs(rgb[:, 1:] - rgb[:, :-1]).mean(-1) < 0.08 * lum[:, 1:]
    return int((pair & same & (lum[:, 1:] > 50) & (lum[:, :-1] > 50) & (np.abs(d[:, 1:] - d[:, :-1]) > 2.0)).sum())


def test_depth_edges_without_colour_edges(realistic, ideal) -> None:  # type: ignore[no-untyped-def]
    assert sum(f.meta["cars"]["camouflaged"] for f in realistic) > 0
    assert sum(f.meta["camouflaged_poles"] for f in realistic) > 0
    hidden, before = sum(map(_hidden_edges, realistic)), sum(map(_hidden_edges, ideal))
    assert hidden > 4 * before + 100, (hidden, before)  # the ideal style has next to none


# --- domains (the rig and the look) -------------------------------------------------------------------------


def test_source_domain_is_the_default_and_names_are_checked() -> None:
    from semattnet.synthetic.domain import SOURCE, Domain

    a, b = make_frame(64, 128, seed=3), make_frame(64, 128, seed=3, domain=SOURCE)
    for k in ("rgb", "sparse", "gt", "lidar_points", "T_cam_lidar"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    with pytest.raises(ValueError, match="unknown synthetic domain 'moon'"):
        make_frame(64, 128, domain="moon")
    with pytest.raises(ValueError, match="beams"):
        Domain(beams=1)


def test_target_domain_has_its_own_rig() -> None:
    """The target's camera (height, pitch, K) and LiDAR (beams, mounting) are what its Domain says, and the
    depth, the scan and the ground truth agree through them."""
    from semattnet.geometry import transform_points
    from semattnet.synthetic.domain import TARGET, Pose

    h, w = 128, 352
    src, f = make_frame(h, w, seed=4, style="realistic"), make_frame(h, w, seed=4, style="realistic", domain="target")
    assert f.K[0, 0] == pytest.approx(0.8 * src.K[0, 0]) and f.K[1, 2] == 64.0
    assert f.meta["domain"] == "target" and "domain" not in src.meta
    assert not np.array_equal(f.T_cam_lidar, src.T_cam_lidar)
    cam = Pose.of_camera(TARGET)
    road = (f.labels == _ID["road"]) & (f.depth > 5)
    street = depth_to_points(f.depth, f.K, mask=road).xyz @ cam.R.T + cam.position
    np.testing.assert_allclose(street[:, 1], CAM_HEIGHT, atol=1e-4)  # the camera is 1.3 m up, pitched 3 deg
    assert f.lidar_points is not None and f.T_cam_lidar is not None
    in_street = transform_points(f.T_cam_lidar, f.lidar_points) @ cam.R.T + cam.position
    ground = in_street[:, 1] > CAM_HEIGHT - 0.1
    assert ground.mean() > 0.3 and np.abs(in_street[ground, 1] - CAM_HEIGHT).max() < 0.1  # 2 cm range noise
    elevation = np.degrees(np.arcsin(f.lidar_points[:, 2] / np.linalg.norm(f.lidar_points, axis=1)))
    assert len(np.unique(np.round(elevation))) == TARGET.n_beams(h)
    assert TARGET.n_beams(h) == 12 and (f.sparse > 0).mean() < 0.8 * (src.sparse > 0).mean()
    depth = project_points(f.lidar_points, f.K, f.T_cam_lidar, (w, h))
    np.testing.assert_array_equal(np.round(depth * DEPTH_SCALE) / DEPTH_SCALE, f.sparse)
    v = f.sparse > 0
    assert np.mean(np.abs(f.sparse[v] - f.depth[v]) < 0.03 * f.depth[v]) > 0.93
    gt = f.gt > 0
    np.testing.assert_allclose(f.gt[gt], f.depth[gt], atol=1 / 512 + 1e-6)
