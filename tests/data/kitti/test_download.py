"""``semattnet data download`` against a local mirror: fake KITTI archives built from the real sample."""

from __future__ import annotations

import functools
import threading
import zipfile
from collections.abc import Iterator
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.archives import UnsafeArchiveError, extract_zip
from semattnet.data.io import read_image, write_image
from semattnet.data.kitti import server as kf
from semattnet.data.kitti.download import drives_for, parse_what
from semattnet.palette import ids_to_colors
from tests._helpers import SAMPLE, online_cache

DRIVE = "2011_09_26_drive_0035_sync"


class _Quiet(SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture
def mirror(tmp_path: Path) -> Iterator[tuple[str, Path, list[str]]]:
    """An HTTP server on 127.0.0.1 serving a folder; yields (prefix URL, folder, requested paths)."""
    root = tmp_path / "mirror"
    root.mkdir()
    seen: list[str] = []

    class Handler(_Quiet):
        def do_GET(self) -> None:
            seen.append(self.path)
            super().do_GET()

    httpd = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=str(root)))
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}/", root, seen
    httpd.shutdown()
    httpd.server_close()


@pytest.fixture
def env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    cache = tmp_path / "cache"
    online_cache(monkeypatch, cache)
    return cache


def _zip(path: Path, members: dict[str, bytes | Path]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w") as zf:
        for name, body in members.items():
            zf.writestr(name, body.read_bytes() if isinstance(body, Path) else body)
    return path


def _kitti_archives(root: Path, tmp: Path) -> Path:
    """KITTI's server layout with one frame (the real sample); returns a semantic-maps zip."""
    cams = ("02", "03")
    gt = {
        f"train/{DRIVE}/proj_depth/groundtruth/image_{c}/0000000005.png": SAMPLE
        / f"data_depth_annotated/train/{DRIVE}/proj_depth/groundtruth/image_{c}/0000000005.png"
        for c in cams
    }
    velo = {
        k.replace("groundtruth", "velodyne_raw"): Path(
            str(v).replace("annotated", "velodyne").replace("groundtruth", "velodyne_raw")
        )
        for k, v in gt.items()
    }
    _zip(root / "data_depth_annotated.zip", gt)
    _zip(root / "data_depth_velodyne.zip", velo)
    _zip(root / "data_depth_selection.zip", {"depth_selection/README.txt": b"selection"})
    raw = SAMPLE / "kitti_raw/2011_09_26"
    members: dict[str, bytes | Path] = {
        f"2011_09_26/{DRIVE}/image_{c}/data/0000000005.png": raw / DRIVE / f"image_{c}/data/0000000005.png"
        for c in cams
    }
    members[f"2011_09_26/{DRIVE}/velodyne_points/data/0000000005.bin"] = b"\0" * 16
    members[f"2011_09_26/{DRIVE}/image_00/data/0000000005.png"] = b"grey"
    _zip(root / "raw_data/2011_09_26_drive_0035/2011_09_26_drive_0035_sync.zip", members)
    calib = {f"2011_09_26/{p.name}": p for p in raw.glob("calib_*.txt")}
    _zip(root / "raw_data/2011_09_26_calib.zip", calib)
    sem = {}
    for c in cams:
        h, w = read_image(raw / DRIVE / f"image_{c}/data/0000000005.png").shape[:2]
        png = write_image(tmp / f"sem_{c}.png", ids_to_colors(np.zeros((h, w), np.uint8)))
        sem[f"semantic/2011_09_26/{DRIVE}/image_{c}/data/0000000005.png"] = png
    return _zip(tmp / "semantic_maps.zip", sem)


def test_download_unpacks_into_loader_layout_and_check_passes(mirror, env, tmp_path: Path) -> None:
    prefix, root, seen = mirror
    sem = _kitti_archives(root, tmp_path)
    out = tmp_path / "kitti"
    args = [
        "data",
        "download",
        "--what",
        "all",
        "--out",
        str(out),
        "--accept-kitti-license",
        "--mirror",
        prefix,
        "--semantic-archive",
        str(sem),
    ]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert "CC BY-NC-SA 3.0" in res.output
    raw = out / "kitti_raw/2011_09_26" / DRIVE
    assert (raw / "image_02/data/0000000005.png").read_bytes() == (
        SAMPLE / "kitti_raw/2011_09_26" / DRIVE / "image_02/data/0000000005.png"
    ).read_bytes()
    assert not (raw / "velodyne_points").exists() and not (raw / "image_00").exists()
    assert (out / "kitti_raw/2011_09_26/calib_cam_to_cam.txt").is_file()
    assert (out / "data_depth_selection/README.txt").is_file()
    assert (out / "semantic/2011_09_26" / DRIVE / "image_03/data/0000000005.png").is_file()
    # only the drive found in the unpacked annotations was fetched
    assert [p for p in seen if p.startswith("/raw_data/") and "calib" not in p] == [
        "/raw_data/2011_09_26_drive_0035/2011_09_26_drive_0035_sync.zip"
    ]
    assert CliRunner().invoke(main, ["data", "check", str(out)]).exit_code == 0
    # a second run downloads nothing (cached) and unpacks nothing new
    n = len(seen)
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0, again.output
    assert len(seen) == n and "already there" in again.output


def test_dry_run_lists_everything_and_downloads_nothing(tmp_path: Path) -> None:
    out = tmp_path / "kitti"
    prefix = "http://127.0.0.1:9/kitti/"
    res = CliRunner().invoke(
        main, ["data", "download", "--what", "all", "--out", str(out), "--dry-run", "--mirror", prefix]
    )
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    for a in kf.DEPTH_COMPLETION_ARCHIVES:
        assert any(f"{prefix}{a.path}" in line and a.size in line and a.target in line for line in lines)
    for d in kf.TRAIN_DRIVES + kf.VAL_DRIVES:
        base = d.removesuffix("_sync")
        assert f"{prefix}raw_data/{base}/{d}.zip" in res.output
    for date in kf.CALIB_DATES:
        assert f"{prefix}raw_data/{date}_calib.zip" in res.output
    assert "151 drives" in res.output and "[manual]" in res.output and "CC BY-NC-SA 3.0" in res.output
    assert not out.exists()


def test_default_prefix_is_kittis_server(tmp_path: Path) -> None:
    res = CliRunner().invoke(
        main, ["data", "download", "--what", "depth-completion", "--out", str(tmp_path), "--dry-run"]
    )
    assert "https://s3.eu-central-1.amazonaws.com/avg-kitti/data_depth_annotated.zip" in res.output


def test_refuses_without_licence(tmp_path: Path) -> None:
    out = tmp_path / "kitti"
    res = CliRunner().invoke(main, ["data", "download", "--out", str(out), "--mirror", "http://127.0.0.1:9/"])
    assert res.exit_code == 1
    assert "CC BY-NC-SA 3.0" in res.output and "--accept-kitti-license" in res.output
    assert not out.exists()


@pytest.mark.parametrize("bad", ["../evil.txt", "train/../../evil.txt", "/abs/evil.txt", "..\\evil.txt"])
def test_unsafe_members_refuse_the_archive(tmp_path: Path, bad: str) -> None:
    archive = _zip(tmp_path / "bad.zip", {"train/ok.txt": b"ok", bad: b"evil"})
    dest = tmp_path / "a" / "b"
    with pytest.raises(UnsafeArchiveError, match="refusing"):
        extract_zip(archive, dest)
    assert not (dest / "train/ok.txt").exists()
    assert not list(tmp_path.rglob("evil.txt"))


def test_unsafe_archive_through_the_command(mirror, env, tmp_path: Path) -> None:
    prefix, root, _ = mirror
    _zip(root / "data_depth_annotated.zip", {"../evil.txt": b"evil"})
    out = tmp_path / "kitti"
    res = CliRunner().invoke(
        main,
        [
            "data",
            "download",
            "--what",
            "depth-completion",
            "--out",
            str(out),
            "--accept-kitti-license",
            "--mirror",
            prefix,
        ],
    )
    assert res.exit_code == 1 and "refusing" in res.output
    assert not list(tmp_path.rglob("evil.txt"))


def test_parse_what_and_drive_source(tmp_path: Path) -> None:
    assert parse_what("semantic,depth-completion") == ("depth-completion", "semantic")
    assert parse_what("all") == ("depth-completion", "raw-subset", "semantic")
    with pytest.raises(ValueError, match="unknown"):
        parse_what("depth,raw")
    drives, source = drives_for(tmp_path)
    assert len(drives) == 151 and "shipped" in source
    (tmp_path / "data_depth_annotated/val" / DRIVE).mkdir(parents=True)
    assert drives_for(tmp_path)[0] == [DRIVE]


def test_error_classes_and_the_shared_cache() -> None:
    import semattnet.cache as cache
    from semattnet import SemAttNetError
    from semattnet._errors import DataError, InputError
    from semattnet.data.archives import LicenseNotAcceptedError
    from semattnet.data.kitti import download as kitti_download

    assert issubclass(UnsafeArchiveError, DataError) and issubclass(LicenseNotAcceptedError, InputError)
    assert issubclass(LicenseNotAcceptedError, SemAttNetError)
    assert kitti_download.fetch is cache.fetch  # KITTI archives go through the same verified cache as weights
    with pytest.raises(LicenseNotAcceptedError, match="accept-kitti-license"):
        kitti_download.download_kitti("/nonexistent", accept_license=False, log=lambda _: None)
