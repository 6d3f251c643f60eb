"""Bag commands in the ``data`` group: ``data bag-from-kitti`` (write a bag from a KITTI raw drive) and
``data bag-topics`` (what a bag holds)."""

from __future__ import annotations

from pathlib import Path

import click

from semattnet._utils.bounds import MAX_ADDED_POINTS
from semattnet.cli.data import data


@data.command("bag-from-kitti")
@click.option(
    "--drive",
    "drive_dir",
    required=True,
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    help="KITTI raw drive folder (DATE/DATE_drive_NNNN_sync; calibration in its parent).",
)
@click.option(
    "--out", required=True, type=click.Path(path_type=Path), help="The bag: NAME.bag (ROS 1) or a ROS 2 bag folder."
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["ros1", "sqlite3", "mcap"]),
    default=None,
    help="Bag format [ros1 for .bag, else mcap].",
)
@click.option("--camera", default="2", show_default=True, help="KITTI colour camera (2 left, 3 right).")
@click.option("--frames", default=None, help="Frame indices, e.g. 0-10 or 1,3,5 [all].")
@click.option(
    "--compressed",
    type=click.Choice(["png", "jpeg"]),
    default=None,
    help="Also write the images as sensor_msgs/CompressedImage (IMAGE_TOPIC/compressed).",
)
@click.option(
    "--nan-points",
    type=click.IntRange(min=0, max=MAX_ADDED_POINTS),
    default=0,
    show_default=True,
    help="NaN points added to each scan (is_dense false), for testing readers.",
)
@click.option("--overwrite", is_flag=True, help="Replace an existing bag.")
def bag_from_kitti(
    drive_dir: Path,
    out: Path,
    fmt: str | None,
    camera: str,
    frames: str | None,
    compressed: str | None,
    nan_points: int,
    overwrite: bool,
) -> None:
    """Write a ROS bag of a KITTI raw drive: images, Velodyne scans, CameraInfo, /tf_static and /tf (the OXTS
    poses)."""
    from semattnet.robotics.bags import write_kitti_bag

    written = write_kitti_bag(
        drive_dir,
        out,
        camera=camera,
        frames=frames,
        fmt=fmt,
        compressed=compressed,
        nan_points=nan_points,
        overwrite=overwrite,
    )
    click.echo(written.describe())
    t = written.topics
    click.echo(f"image topic {t.image}, points topic {t.points}, camera info topic {t.camera_info}")


@data.command("bag-topics")
@click.argument("bag", type=click.Path(exists=True, path_type=Path))
def bag_topics(bag: Path) -> None:
    """List a bag's topics: name, message type, count and rate."""
    from semattnet.robotics.bags import format_topics, list_topics

    click.echo(format_topics(list_topics(bag)))
