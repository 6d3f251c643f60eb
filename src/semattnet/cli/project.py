"""LiDAR scan -> sparse depth map: ``project``."""

from __future__ import annotations

from pathlib import Path

import click

from semattnet.cli._group import main
from semattnet.cli._options import PERIOD, parse_size, require_with


def _numbers(text: str | None, option: str) -> list[float] | None:
    if text is None:
        return None
    try:
        return [float(v) for v in text.replace(" ", ",").split(",") if v]
    except ValueError:
        raise click.BadParameter(f"expected comma-separated numbers; got {text!r}", param_hint=option) from None


def _size(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    return parse_size(text, "--size", order="WxH")


_EXISTING = click.Path(exists=True, dir_okay=False, path_type=Path)


@main.command()
@click.option(
    "--velodyne",
    "--points",
    "scan",
    required=True,
    type=_EXISTING,
    help="The scan: KITTI .bin, or .npy/.txt/.csv/.ply/.pcd (x, y, z metres in the LiDAR frame).",
)
@click.option(
    "--calib-dir",
    type=click.Path(exists=True, path_type=Path),
    default=None,
    help="KITTI raw date folder (calib_cam_to_cam.txt, calib_velo_to_cam.txt).",
)
@click.option("--camera", default="2", show_default=True, help="KITTI camera id with --calib-dir (2 or 3).")
@click.option("--rig", type=_EXISTING, default=None, help="JSON/YAML rig file: K, T_cam_lidar, image_size.")
@click.option("--K", "K", default=None, metavar="FX,FY,CX,CY", help="Intrinsics in pixels (with --T and --size).")
@click.option("--T", "T", default=None, metavar="16 NUMBERS", help="LiDAR -> camera 4x4, row-major, metres.")
@click.option("--size", default=None, metavar="WxH", help="Image size in pixels (with --K and --T).")
@click.option(
    "--deskew-oxts",
    type=_EXISTING,
    default=None,
    help="KITTI OXTS packet of the frame: ego-motion compensate the scan first (as KITTI's maps are).",
)
@click.option(
    "--scan-period",
    type=PERIOD,
    default=0.1,
    show_default=True,
    help="With --deskew-oxts: seconds per LiDAR revolution (KITTI: timestamps_end - timestamps_start).",
)
@click.option("--out", required=True, type=click.Path(dir_okay=False, path_type=Path), help="16-bit PNG to write.")
@click.option("--overwrite", is_flag=True, help="Replace an existing output.")
def project(
    scan: Path,
    calib_dir: Path | None,
    camera: str,
    rig: Path | None,
    K: str | None,
    T: str | None,
    size: str | None,
    deskew_oxts: Path | None,
    scan_period: float,
    out: Path,
    overwrite: bool,
) -> None:
    """Project a LiDAR scan into a camera: a KITTI-encoded 16-bit sparse depth map (depth * 256)."""
    from semattnet.data.scans import project_scan_file

    require_with("--deskew-oxts", deskew_oxts is not None, "scan_period")
    require_with("--calib-dir", calib_dir is not None, "camera")
    summary = project_scan_file(
        scan,
        out,
        calib_dir=calib_dir,
        camera=camera,
        rig=rig,
        K=_numbers(K, "--K"),
        T=_numbers(T, "--T"),
        image_size=_size(size),
        deskew_oxts=deskew_oxts,
        scan_period=scan_period,
        overwrite=overwrite,
    )
    click.echo(summary.describe())
