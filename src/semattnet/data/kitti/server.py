"""What KITTI depth completion is made of on KITTI's download server: archives, raw drives, terms.

Data only (nothing here downloads); :mod:`semattnet.data.kitti.download` uses it.

Server layout (KITTI's own download links, all under :data:`KITTI_PREFIX`)::

    data_depth_annotated.zip                 train/<drive>/proj_depth/groundtruth/image_0X/*.png
    data_depth_velodyne.zip                  train/<drive>/proj_depth/velodyne_raw/image_0X/*.png
    data_depth_selection.zip                 depth_selection/{val_selection_cropped,test_depth_completion_anonymous}/...
    raw_data/<date>_drive_<nnnn>/<date>_drive_<nnnn>_sync.zip
                                             <date>/<drive>/{image_00..03,oxts,velodyne_points}/...
    raw_data/<date>_calib.zip                <date>/calib_{cam_to_cam,velo_to_cam,imu_to_velo}.txt

The drive lists are a fallback for ``--dry-run`` before anything is downloaded: the real run takes
the drives from the unpacked ``data_depth_annotated/{train,val}/`` folders, which are the
benchmark's definition of its split. :data:`VAL_DRIVES` is the official validation split (13 drives,
the drives named in ``val_selection_cropped``). :data:`TRAIN_DRIVES` was not checked name by name
against the official training split: it is KITTI raw's catalogue of synced drives (city,
residential, road, campus, person) without the five calibration recordings and without the
validation drives. It has 138 drives, the size of the official training split.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "CALIB_DATES",
    "DEPTH_COMPLETION_ARCHIVES",
    "KITTI_LICENSE",
    "KITTI_PREFIX",
    "SEMANTIC_MAPS",
    "TRAIN_DRIVES",
    "VAL_DRIVES",
    "KittiArchive",
    "calib_archive",
    "raw_drive_archive",
]

#: KITTI's official download server (the links on cvlibs.net point here).
KITTI_PREFIX = "https://s3.eu-central-1.amazonaws.com/avg-kitti/"

KITTI_LICENSE = (
    "KITTI is licensed under Creative Commons Attribution-NonCommercial-ShareAlike 3.0 (CC BY-NC-SA 3.0): "
    "non-commercial use only, attribute (Geiger et al. IJRR 2013; Uhrig et al. 3DV 2017), share alike. "
    "https://www.cvlibs.net/datasets/kitti/"
)


@dataclass(frozen=True)
class KittiArchive:
    """One archive on the server and where its contents go under the output root.

    Attributes:
        path: path below the server prefix, e.g. ``data_depth_annotated.zip``.
        target: folder under the output root the archive unpacks into.
        size: size as KITTI's download page states it (approximate, for display), or None.
        strip: leading folder names removed from member paths (the first that matches).
        keep: only members whose path contains one of these folder names (empty: all).
    """

    path: str
    target: str
    size: str | None = None
    strip: tuple[str, ...] = ()
    keep: tuple[str, ...] = ()

    @property
    def file_name(self) -> str:
        return self.path.rsplit("/", 1)[-1]


DEPTH_COMPLETION_ARCHIVES = (
    KittiArchive("data_depth_annotated.zip", "data_depth_annotated", "14 GB", strip=("data_depth_annotated",)),
    KittiArchive("data_depth_velodyne.zip", "data_depth_velodyne", "5 GB", strip=("data_depth_velodyne",)),
    KittiArchive(
        "data_depth_selection.zip", "data_depth_selection", "2 GB", strip=("depth_selection", "data_depth_selection")
    ),
)

#: Only the colour cameras are kept from a raw drive (the benchmark's image_02 / image_03).
RAW_KEEP = ("image_02", "image_03")


def raw_drive_archive(drive: str) -> KittiArchive:
    """The raw-data zip of ``<date>_drive_<nnnn>_sync``; unpacks to ``kitti_raw/<date>/<drive>/image_0{2,3}``."""
    base = drive.removesuffix("_sync")
    return KittiArchive(f"raw_data/{base}/{base}_sync.zip", "kitti_raw", None, keep=RAW_KEEP)


def calib_archive(date: str) -> KittiArchive:
    """The calibration zip of one recording day; unpacks to ``kitti_raw/<date>/calib_*.txt``."""
    return KittiArchive(f"raw_data/{date}_calib.zip", "kitti_raw", None)


#: Where the SemAttNet authors' precomputed semantic maps are. Their README links a Google Drive
#: folder; its id is not recorded in this project's spec or paper, so it is not guessed here.
SEMANTIC_MAPS = {
    "url": None,
    "target": "semantic",
    "instructions": (
        "The authors' semantic maps are not on KITTI's server: download them by hand from the link in "
        "https://github.com/danishnazir/SemAttNet (README, 'Semantic maps'), then pass the file with "
        "--semantic-archive PATH_OR_URL (it is unpacked into ROOT/semantic), or make your own with "
        "`semattnet segment --model hf:default --images ROOT/kitti_raw --out ROOT/semantic`."
    ),
}

#: The official validation drives (data_depth_annotated/val; the drives of val_selection_cropped).
VAL_DRIVES = (
    "2011_09_26_drive_0002_sync",
    "2011_09_26_drive_0005_sync",
    "2011_09_26_drive_0013_sync",
    "2011_09_26_drive_0020_sync",
    "2011_09_26_drive_0023_sync",
    "2011_09_26_drive_0036_sync",
    "2011_09_26_drive_0079_sync",
    "2011_09_26_drive_0095_sync",
    "2011_09_26_drive_0113_sync",
    "2011_09_28_drive_0037_sync",
    "2011_09_29_drive_0026_sync",
    "2011_09_30_drive_0016_sync",
    "2011_10_03_drive_0047_sync",
)


def _drives(date: str, numbers: str) -> tuple[str, ...]:
    return tuple(f"{date}_drive_{int(n):04d}_sync" for n in numbers.split())


# KITTI raw's synced drives by day (calibration recordings 09_26/0119, 09_28/0225, 09_29/0108,
# 09_30/0072 and 10_03/0058 left out: they have no depth-completion annotations).
_RAW_DRIVES = (
    _drives(
        "2011_09_26",
        "1 2 5 9 11 13 14 15 17 18 19 20 22 23 27 28 29 32 35 36 39 46 48 51 52 56 57 "
        "59 60 61 64 70 79 84 86 87 91 93 95 96 101 104 106 113 117",
    )
    + _drives(
        "2011_09_28",
        "1 2 16 21 34 35 37 38 39 43 45 47 53 54 57 65 66 68 70 71 75 77 78 80 82 86 "
        "87 89 90 94 95 96 98 100 102 103 104 106 108 110 113 117 119 121 122 125 126 "
        "128 132 134 135 136 138 141 143 145 146 149 153 154 155 156 160 161 162 165 "
        "166 167 168 171 174 177 179 183 184 185 186 187 191 192 195 198 199 201 204 "
        "205 208 209 214 216 220 222",
    )
    + _drives("2011_09_29", "4 26 71")
    + _drives("2011_09_30", "16 18 20 27 28 33 34")
    + _drives("2011_10_03", "27 34 42 47")
)

#: Training drives (unverified fallback, see the module docstring).
TRAIN_DRIVES = tuple(d for d in _RAW_DRIVES if d not in VAL_DRIVES)

#: Recording days of all drives (one calibration zip each).
CALIB_DATES = tuple(sorted({d[:10] for d in _RAW_DRIVES}))
