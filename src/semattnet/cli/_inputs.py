"""The inputs ``predict`` reads, as one table: each kind of input, the options it owns and how it makes its source.

An :class:`InputKind` declares its options (listed under its heading in ``predict --help``), the options that
choose it, the shared semantic-map options it takes, what it offers the outputs (a recording with LiDAR,
frames the viewer can show) and a dataclass of its parsed values that checks them and builds the
:class:`~semattnet.data.frames.IndexedSource`. One rule covers every kind (:func:`choose_input`): exactly one
kind is chosen, and an option of another kind is a usage error naming the kinds it belongs to. A kind added to
:data:`INPUTS` gets its options, its heading and the rule with no other code.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import click

from semattnet.cli._model import palette_mismatch_option
from semattnet.cli._options import SECONDS
from semattnet.cli._params import given, section, values_of, with_options
from semattnet.data.datasets import DATASETS, DEFAULT_DATASET

if TYPE_CHECKING:
    import numpy as np

    from semattnet.data.frames import IndexedSource
    from semattnet.inference.semantic import SemanticMaps

__all__ = ["INPUTS", "ChosenInput", "InputKind", "InputValues", "Maps", "choose_input", "input_options", "or_list"]

FILES, RAW, BAG, DATASET = "Inputs: files", "Inputs: KITTI raw drive", "Inputs: ROS bag", "Inputs: dataset"
SEMANTIC = "Semantic maps"
_INPUT = click.Path(exists=True, path_type=Path)
_FOLDER = click.Path(exists=True, file_okay=False, path_type=Path)
_F = TypeVar("_F", bound=Callable[..., object])


def or_list(items: Sequence[str]) -> str:
    """``a``, ``a or b``, ``a, b or c``."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} or {items[-1]}"


def intrinsics(text: str | None) -> np.ndarray | None:
    """``--K`` as a (3, 3) matrix, or None (a bad value: a usage error of ``--K``)."""
    from semattnet._errors import SemAttNetError
    from semattnet.viz.viewer import parse_intrinsics

    try:
        return parse_intrinsics(text) if text else None
    except SemAttNetError as exc:
        raise click.BadParameter(str(exc), param_hint="--K") from None
    except ValueError:
        raise click.BadParameter(f"expected fx,fy,cx,cy or kitti, got {text!r}", param_hint="--K") from None


@dataclass(frozen=True)
class Maps:
    """Where the semantic maps come from: ``--semantic`` (files), ``--segment`` (a segmenter SPEC) and what to do
    with maps of another palette (``--palette-mismatch``)."""

    semantic: Path | None
    segment_spec: str | None
    palette_mismatch: str

    def semantic_maps(self, folder: bool) -> SemanticMaps:
        """The maps' filler of a source that reads maps from a folder (``folder``) or none."""
        from semattnet.inference.semantic import SemanticMaps

        return SemanticMaps(self.segment_spec, folder=folder, mismatch=self.palette_mismatch)


#: The semantic-map options: --semantic and --segment belong to the kinds whose ``accepts`` names them.
MAP_OPTIONS = (
    section(SEMANTIC)(["--semantic"], type=_INPUT, default=None,
                      help="PNG file or folder of colour-coded semantic maps (with --rgb, --kitti-raw or --data)."),
    section(SEMANTIC)(["--segment", "segment_spec"], default=None, metavar="SPEC",
                      help="With --kitti-raw or --bag: segment each image with this model (see `semattnet segment "
                      "--model`); with --data (nyuv2, void): the split's frames segmented once into a cache folder "
                      "and reused."),
    palette_mismatch_option(section(SEMANTIC)),
)  # fmt: skip


@dataclass(frozen=True)
class InputValues:
    """The parsed options of one input kind (its fields: the kind's option names)."""

    def check(self, maps: Maps) -> None:
        """Usage errors among the kind's own options (before any work)."""

    def listing(self) -> str | None:
        """What to print instead of a run (``--list-topics``), or None."""
        return None

    def has_intrinsics(self) -> bool:
        """Whether the frames come with the camera's intrinsics."""
        return True

    def source(self, semantic: Path | None) -> IndexedSource:
        """The frames (``semantic``: the folder or file of their semantic maps, or None)."""
        raise NotImplementedError  # every kind's values define it

    def open(self, maps: Maps, device: str) -> tuple[IndexedSource, SemanticMaps]:
        """The source and the filler of its missing semantic maps."""
        filler = maps.semantic_maps(folder=maps.semantic is not None)
        return self.source(maps.semantic), filler


@dataclass(frozen=True)
class FilesInput(InputValues):
    """``--rgb`` / ``--sparse`` (and ``--K``): the user's own files or folders, paired by name."""

    rgb: Path | None
    sparse: Path | None
    intrinsics: str | None

    def check(self, maps: Maps) -> None:
        if self.rgb is None or self.sparse is None:
            raise click.UsageError("--rgb and --sparse go together: give both")
        intrinsics(self.intrinsics)

    def has_intrinsics(self) -> bool:
        return self.intrinsics is not None

    def source(self, semantic: Path | None) -> IndexedSource:
        from semattnet.data.sources import FolderSource

        assert self.rgb is not None and self.sparse is not None  # checked
        return FolderSource.pair(self.rgb, self.sparse, semantic, K=intrinsics(self.intrinsics), missing_ok=True)


@dataclass(frozen=True)
class RawDriveInput(InputValues):
    """``--kitti-raw``: a KITTI raw drive (images, Velodyne scans, calibration, OXTS)."""

    kitti_raw: Path
    frames: str | None
    camera: str
    deskew: bool

    def source(self, semantic: Path | None) -> IndexedSource:
        from semattnet.data.sources import RawDriveSource

        return RawDriveSource(self.kitti_raw, self.frames, self.camera, semantic, self.deskew)


@dataclass(frozen=True)
class BagInput(InputValues):
    """``--bag``: a ROS 1 or ROS 2 recording of a camera and a LiDAR."""

    bag: Path
    image_topic: str | None
    points_topic: str | None
    camera_info_topic: str | None
    rig: Path | None
    semantic_topic: str | None
    max_skew: float | None
    list_topics: bool

    def check(self, maps: Maps) -> None:
        if not self.list_topics and None in (self.image_topic, self.points_topic):
            raise click.UsageError("--bag needs --image-topic and --points-topic (see --list-topics)")
        if self.semantic_topic is not None and maps.segment_spec is not None:
            raise click.UsageError("give --semantic-topic or --segment, not both")

    def listing(self) -> str | None:
        from semattnet.robotics.bags import format_topics, list_topics

        return format_topics(list_topics(self.bag)) if self.list_topics else None

    def source(self, semantic: Path | None) -> IndexedSource:
        from semattnet.robotics import BagSource

        assert self.image_topic is not None and self.points_topic is not None  # checked
        return BagSource(self.bag, self.image_topic, self.points_topic, self.camera_info_topic, self.rig,
                         self.max_skew, self.semantic_topic, log=click.echo)  # fmt: skip

    def open(self, maps: Maps, device: str) -> tuple[IndexedSource, SemanticMaps]:
        return self.source(None), maps.semantic_maps(folder=self.semantic_topic is not None)


@dataclass(frozen=True)
class DatasetInput(InputValues):
    """``--data --dataset --split``: a split of a registered dataset."""

    data_root: Path
    dataset: str
    split: str | None

    def source(self, semantic: Path | None) -> IndexedSource:
        from semattnet.data.datasets import get_dataset

        return get_dataset(self.dataset).source(self.data_root, self.split, semantic_root=semantic)

    def open(self, maps: Maps, device: str) -> tuple[IndexedSource, SemanticMaps]:
        """With ``--segment``: the split's maps, segmented once into a cache folder, read as a folder."""
        from semattnet.data.datasets import get_dataset
        from semattnet.segmentation.datasets import segment_split

        if maps.segment_spec is None or maps.semantic is not None:  # (both: refused by the maps' filler)
            return super().open(maps, device)
        split = self.split or get_dataset(self.dataset).eval_split
        folder = segment_split(self.dataset, self.data_root, (split,), maps.segment_spec, device, log=click.echo)
        return self.source(folder), Maps(None, None, maps.palette_mismatch).semantic_maps(folder=True)


@dataclass(frozen=True)
class InputKind:
    """One kind of input: its ``options`` (listed under their heading), the parameter names that choose it
    (``selects``), how the one-input error names it (``usage``), the semantic-map options it takes
    (``accepts``), its values' dataclass; ``recording``: a timed recording of a camera and a LiDAR (point
    clouds, a bird's-eye view, a real-time replay); ``report``: the viewer (``--report``) can show its frames."""

    name: str
    usage: str
    options: tuple[click.Option, ...]
    values: type[InputValues]
    selects: tuple[str, ...]
    accepts: tuple[str, ...] = ()
    recording: bool = False
    report: bool = False

    @property
    def flag(self) -> str:
        """The option naming this kind in errors (``--rgb``)."""
        return next(o.opts[0] for o in self.options if o.name == self.selects[0])

    def takes(self, name: str) -> bool:
        """Whether option ``name`` means something with this kind."""
        return name in self.accepts or any(o.name == name for o in self.options)


#: Every kind of input ``predict`` reads, in the order of its ``--help``.
INPUTS: tuple[InputKind, ...] = (
    InputKind("files", "--rgb and --sparse", (
        section(FILES)(["--rgb"], type=_INPUT, default=None, help="PNG file or folder (with --sparse)."),
        section(FILES)(["--sparse"], type=_INPUT, default=None, help="16-bit PNG file or folder (with --rgb)."),
        section(FILES)(["--K", "intrinsics"], default=None, metavar="fx,fy,cx,cy|kitti",
                       help="The camera's intrinsics ('kitti': KITTI's camera 02): for --report's 3D view and the "
                       "clouds of --bag-out, --rerun and --live."),
    ), FilesInput, selects=("rgb", "sparse"), accepts=("semantic",), report=True),
    InputKind("kitti-raw", "--kitti-raw", (
        section(RAW)(["--kitti-raw"], type=_FOLDER, default=None,
                     help="A KITTI raw drive folder RAW_ROOT/DATE/DATE_drive_NNNN_sync (instead of --rgb/--sparse)."),
        section(RAW)(["--frames"], default=None, help="Indices, a range a-b or a comma list (default all)."),
        section(RAW)(["--camera"], type=click.Choice(["2", "3"]), default="2", show_default=True,
                     help="The colour camera: image_02 or image_03."),
        section(RAW)(["--deskew"], is_flag=True, help="Ego-motion compensate the scans with their OXTS data."),
    ), RawDriveInput, selects=("kitti_raw",), accepts=("semantic", "segment_spec"), recording=True),
    InputKind("bag", "--bag", (
        section(BAG)(["--bag"], type=_INPUT, default=None,
                     help="A ROS 1 .bag, a ROS 2 bag folder or a .db3 / .mcap file (instead of --rgb/--sparse)."),
        section(BAG)(["--image-topic"], default=None, help="sensor_msgs/Image or CompressedImage topic."),
        section(BAG)(["--points-topic"], default=None, help="sensor_msgs/PointCloud2 topic (x, y, z)."),
        section(BAG)(["--camera-info-topic"], default=None, help="sensor_msgs/CameraInfo topic [the bag's only one]."),
        section(BAG)(["--rig"], type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
                     help="Rig JSON (K, T_cam_lidar, image_size) overriding CameraInfo and /tf_static."),
        section(BAG)(["--semantic-topic"], default=None,
                     help="Colour-coded semantic images, paired with the images by stamp."),
        section(BAG)(["--max-skew"], type=SECONDS, default=None,
                     help="Seconds between an image and its scan at most [half the scan period]."),
        section(BAG)(["--list-topics"], is_flag=True, help="Print the bag's topics and exit."),
    ), BagInput, selects=("bag",), accepts=("segment_spec",), recording=True),
    InputKind("dataset", "--data (with --dataset)", (
        section(DATASET)(["--data", "data_root"], type=_FOLDER, default=None,
                         help="A dataset root (instead of --rgb/--sparse): the frames of --split."),
        section(DATASET)(["--dataset"], type=click.Choice(list(DATASETS)), default=DEFAULT_DATASET,
                         show_default=True, help="The dataset whose root --data is."),
        section(DATASET)(["--split"], default=None, help="The split [the dataset's evaluation split]."),
    ), DatasetInput, selects=("data_root",), accepts=("semantic", "segment_spec")),
)  # fmt: skip


def input_options(kinds: Sequence[InputKind] = INPUTS) -> Callable[[_F], _F]:
    """The options of every kind in ``kinds``, then the semantic-map options, under their headings."""
    return with_options([o for kind in kinds for o in kind.options] + list(MAP_OPTIONS))


@dataclass(frozen=True)
class ChosenInput:
    """The kind of input the options chose, its checked values and the semantic-map options."""

    kind: InputKind
    values: InputValues
    maps: Maps


def choose_input(ctx: click.Context, kinds: Sequence[InputKind] = INPUTS) -> ChosenInput:
    """Exactly one kind of input, no option of another kind, then the kind's own checks (usage errors)."""
    chosen = [kind for kind in kinds if any(given(ctx, name) for name in kind.selects)]
    if len(chosen) != 1:
        several = f" (one of them: not {' and '.join(k.flag for k in chosen)})" if chosen else ""
        raise click.UsageError("give " + ", or ".join(k.usage for k in kinds) + several)
    kind = chosen[0]
    flags = {p.name: p.opts[0] for p in ctx.command.params}
    for name in dict.fromkeys(n for k in kinds for n in (*(str(o.name) for o in k.options), *k.accepts)):
        if given(ctx, name) and not kind.takes(name):
            owners = [k.flag for k in kinds if k.takes(name)]
            raise click.UsageError(f"{flags.get(name, name)} is an option of {or_list(owners)}, not of {kind.flag}")
    picked = ChosenInput(kind, values_of(kind.values, ctx.params), values_of(Maps, ctx.params))
    picked.values.check(picked.maps)
    return picked
