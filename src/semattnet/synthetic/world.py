"""A randomised "generalist" synthetic world: streets and indoor rooms, random rigs, random sparse patterns.

:func:`make_world_frame` draws one frame from its seed: the kind (:data:`WORLD_KINDS`: a street of
:func:`~.scenes.make_scene`, either of :data:`~.scenes.SCENE_STYLES`, or a room of :func:`~.rooms.make_room`), the
sparse pattern (:data:`WORLD_PATTERNS`, :mod:`.patterns`; streets: LiDAR 60 %, points 20 %, depth camera 20 %;
rooms: points 45 %, depth camera 35 %, LiDAR 20 %), the image size (160-384 rows, 256-1240 columns, both multiples
of 8, width / height 1.2-4), the intrinsics (horizontal field of view 50-100 deg, square pixels, the principal
point within 10 % of the image's size from its centre), the camera (streets: 1.0-2.4 m up, pitched 3 deg up to
8 deg down; rooms: see :mod:`.rooms`), the LiDAR rig (:func:`~.patterns.random_rig`) and the look (streets: the
sun from ahead, above or a little behind, exposure 0.5-1.3; rooms: 0.55-1.3; image noise 0-4 %; then a colour gain
of 0.7-1.3 per channel and a gamma of 0.8-1.25 on the whole image). The ground truth is the exact depth of every
pixel with a surface within :data:`WORLD_RANGES` (streets 0.5-80 m, rooms 0.5-10 m); the sparse depth stays in the
same range. A frame with fewer than :data:`MIN_SPARSE` sparse points is drawn again (the pattern up to 3 times, then
the whole frame, up to 8 times; after that, as a last resort, random points, said in ``meta["fallback_from"]``).

:func:`world_seed` numbers the frames of :data:`WORLD_SPLITS` so that no two splits share a seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from semattnet._errors import InputError

from .domain import Domain, Pose
from .layout import Box
from .materials import LABEL_COLOURS, MATERIAL_IDS
from .patterns import PATTERNS, Options, depthcam_pattern, lidar_pattern, points_pattern, random_rig
from .raycast import camera_view
from .rooms import make_room, shoot_room
from .scenes import SCENE_STYLES, Shot, make_scene, shoot

__all__ = [
    "HELDOUT_CELLS",
    "MIN_SPARSE",
    "PATTERN_OPTIONS",
    "WORLD_KINDS",
    "WORLD_PATTERNS",
    "WORLD_RANGES",
    "WORLD_SPLITS",
    "WorldFrame",
    "make_world_frame",
    "random_intrinsics",
    "random_size",
    "world_seed",
]

#: What a world frame shows.
WORLD_KINDS: tuple[str, ...] = ("street", "indoor")
#: The sparse patterns of a world frame (:mod:`.patterns`).
WORLD_PATTERNS: tuple[str, ...] = PATTERNS
#: Splits whose seeds (:func:`world_seed`) never overlap.
WORLD_SPLITS: tuple[str, ...] = ("train", "heldout")
#: The depth range (metres) of the ground truth and the sparse depth, by kind.
WORLD_RANGES: dict[str, tuple[float, float]] = {"street": (0.5, 80.0), "indoor": (0.5, 10.0)}
#: Every frame has at least this many sparse points.
MIN_SPARSE = 20
#: The options :func:`make_world_frame` passes to each pattern (:mod:`.patterns`; ``beams``: the LiDAR's).
PATTERN_OPTIONS: dict[str, tuple[str, ...]] = {
    "lidar": ("beams",),
    "points": ("count", "noise"),
    "depthcam": ("max_range", "factor"),
}
#: The held-out cells, one per kind of scene and sparse pattern: ``(name, kind, pattern, options)``. The zero-shot
#: benchmark scores each (frames from index 0 of the held-out split); the generalists' uncertainty is calibrated
#: on each (frames from ``semattnet.training.generalist.CALIBRATION_FIRST`` on).
HELDOUT_CELLS: tuple[tuple[str, str, str, dict[str, int]], ...] = (
    ("street/lidar", "street", "lidar", {}),
    ("street/points", "street", "points", {}),
    ("street/depthcam", "street", "depthcam", {}),
    ("indoor/points500", "indoor", "points", {"count": 500}),
    ("indoor/depthcam", "indoor", "depthcam", {}),
    ("indoor/lidar", "indoor", "lidar", {}),
)
_ODDS = {"street": (0.6, 0.2, 0.2), "indoor": (0.2, 0.45, 0.35)}  # lidar, points, depthcam
_TAG = 0x574F524C44  # the world's own stream of seeds
_ATTEMPTS, _PATTERN_TRIES = 8, 3


@dataclass
class WorldFrame:
    """One frame of the world: images (H, W, 3) uint8, depths (H, W) float32 metres (0 = none), K (3, 3)."""

    rgb: np.ndarray
    semantic: np.ndarray  # Cityscapes colours (LABEL_COLOURS[labels])
    sparse: np.ndarray  # 0 = missing
    gt: np.ndarray  # the exact depth of every pixel with a surface within WORLD_RANGES[kind], 0 = none (sky)
    K: np.ndarray
    kind: str
    pattern: str
    meta: dict[str, object] = field(default_factory=dict)


def world_seed(split: str, index: int) -> int:
    """The seed of frame ``index`` (0, 1, ...) of ``split`` (one of :data:`WORLD_SPLITS`): splits interleave, so
    no two share a seed.

    Raises:
        InputError: an unknown split or a negative index.
    """
    if split not in WORLD_SPLITS:
        raise InputError(f"split: unknown world split {split!r}; expected one of {', '.join(WORLD_SPLITS)}")
    if index < 0:
        raise InputError(f"index: must be 0 or more, got {index}")
    return int(index) * len(WORLD_SPLITS) + WORLD_SPLITS.index(split)


def random_size(rng: np.random.Generator) -> tuple[int, int]:
    """A random (H, W): H 160-384, W 256-1240, both multiples of 8, W / H 1.2-4."""
    height = 8 * int(rng.integers(20, 49))
    low, high = max(256, int(np.ceil(1.2 * height / 8)) * 8), min(1240, 4 * height)
    return height, 8 * int(rng.integers(low // 8, high // 8 + 1))


def random_intrinsics(rng: np.random.Generator, size: tuple[int, int]) -> tuple[np.ndarray, float]:
    """(3, 3) intrinsics of a random lens for ``size`` (H, W) and its horizontal field of view (50-100 deg): square
    pixels, the principal point within 10 % of the size from the image's centre."""
    height, width = size
    hfov = float(rng.uniform(50, 100))
    f = width / 2 / np.tan(np.deg2rad(hfov) / 2)
    cx, cy = (width - 1) / 2 + rng.uniform(-0.1, 0.1) * width, (height - 1) / 2 + rng.uniform(-0.1, 0.1) * height
    return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]]), hfov


@dataclass
class _Scene:
    """A kind's picture and what the patterns need of it."""

    shot: Shot
    boxes: list[Box]
    camera: Pose
    surface: np.ndarray | None  # (H, W) box index per pixel (None: not cast yet)
    realistic: bool
    meta: dict[str, object]


def _street(rng: np.random.Generator, K: np.ndarray, size: tuple[int, int]) -> _Scene:
    """A street of either style seen by a random camera (1.0-2.4 m up, 3 deg up to 8 deg down) in random light."""
    style = SCENE_STYLES[int(rng.integers(len(SCENE_STYLES)))]
    height, pitch, noise = float(rng.uniform(1.0, 2.4)), float(rng.uniform(-3, 8)), float(rng.uniform(0, 0.04))
    rig = Domain("world", camera_height=height, camera_pitch=pitch, exposure=(0.5, 1.3), noise=noise)
    rig = replace(rig, sun_x=(-0.9, 0.9), sun_z=(-0.3, 1.2))  # the sun from ahead, above or a little behind
    scene = make_scene(rng, style, rig)
    camera = Pose.of_camera(rig)
    shot = shoot(scene, K, size, camera, rng)
    meta = {"style": style, "shadow": scene.shadow, "camera_height": height, "pitch": -pitch}
    meta |= {"exposure": scene.exposure, "image_noise": noise}
    return _Scene(shot, scene.boxes, camera, None, scene.dressing is not None, meta)


def _indoor(rng: np.random.Generator, K: np.ndarray, size: tuple[int, int]) -> _Scene:
    """A furnished room (:func:`~.rooms.make_room`) in random light."""
    room = make_room(rng)
    exposure, noise = float(rng.uniform(0.55, 1.3)), float(rng.uniform(0, 0.04))
    shot, surface = shoot_room(room, K, size, rng, exposure, noise)
    meta = room.meta | {"exposure": exposure, "image_noise": noise}
    return _Scene(shot, room.boxes, room.camera, surface, False, meta)


def _grade(rgb: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, dict[str, object]]:
    """The image with a colour gain of 0.7-1.3 per channel, then a gamma of 0.8-1.25."""
    gain, gamma = rng.uniform(0.7, 1.3, 3), float(rng.uniform(0.8, 1.25))
    out = 255.0 * np.clip(rgb / 255.0 * gain, 0.0, 1.0) ** gamma
    return np.round(out).astype(np.uint8), {"colour_gain": gain.tolist(), "gamma": gamma}


def _sparse(
    rng: np.random.Generator,
    pattern: str,
    scene: _Scene,
    K: np.ndarray,
    gt: np.ndarray,
    kind: str,
    options: Options,
) -> tuple[np.ndarray, dict[str, object]]:
    """The ``pattern`` of the frame (with its ``options``, :data:`PATTERN_OPTIONS`), in range."""
    low, high = WORLD_RANGES[kind]
    height, width = gt.shape
    if pattern == "lidar":
        hfov = float(np.rad2deg(2 * np.arctan(width / 2 / K[0, 0])))
        pitch = float(np.rad2deg(np.arcsin(scene.camera.R[1, 2])))  # degrees down: the optical axis' y (down)
        rig = random_rig(rng, pitch, hfov, width, indoor=kind == "indoor")
        rig = replace(rig, beams=int(options["beams"])) if "beams" in options else rig
        sparse, info = lidar_pattern(gt, K, rng, scene.boxes, scene.camera, rig, scene.realistic)
        return np.where((sparse >= low) & (sparse <= high), sparse, 0.0).astype(np.float32), info
    if pattern == "points":
        sparse, info = points_pattern(gt, K, rng, **options)
    else:
        if scene.surface is None:
            scene.surface = camera_view(K, height, width, scene.boxes, scene.camera).idx.reshape(height, width)
        absorbing = scene.shot.material != MATERIAL_IDS["matte"]  # the realistic style's dark, glossy paint and glass
        sparse, info = depthcam_pattern(gt, K, rng, scene.surface, absorbing, **options)
    return np.where(sparse > 0, np.clip(sparse, low, high), 0.0).astype(np.float32), info


def _attempt(seed: int, attempt: int, kind: str, pattern: str, size: tuple[int, int], options: Options) -> WorldFrame:
    """One draw of the frame: the first of up to :data:`_PATTERN_TRIES` sparse patterns with :data:`MIN_SPARSE`
    points, else the last."""
    rng = np.random.default_rng((_TAG, seed, attempt + 1))
    K, hfov = random_intrinsics(rng, size)
    scene = (_street if kind == "street" else _indoor)(rng, K, size)
    low, high = WORLD_RANGES[kind]
    depth = scene.shot.depth
    gt = np.where((depth >= low) & (depth <= high), depth, 0.0).astype(np.float32)
    rgb, look = _grade(scene.shot.rgb, rng)
    for _ in range(_PATTERN_TRIES):
        sparse, info = _sparse(rng, pattern, scene, K, gt, kind, options)
        if np.count_nonzero(sparse) >= MIN_SPARSE:
            break
    meta = {"seed": seed, "attempt": attempt, "size": list(size), "hfov": hfov, **scene.meta, **look, "sparse": info}
    return WorldFrame(rgb, LABEL_COLOURS[scene.shot.labels], sparse, gt, K, kind, pattern, meta)


def _check(seed: int, kind: str | None, pattern: str | None, size: tuple[int, int] | None, options: Options) -> None:
    """Raise :class:`~semattnet.InputError` on a bad argument of :func:`make_world_frame`."""
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed: must be an integer 0 or more, got {seed!r}")
    if kind is not None and kind not in WORLD_KINDS:
        raise InputError(f"kind: unknown world kind {kind!r}; expected one of {', '.join(WORLD_KINDS)}")
    if pattern is not None and pattern not in WORLD_PATTERNS:
        raise InputError(f"pattern: unknown sparse pattern {pattern!r}; expected one of {', '.join(WORLD_PATTERNS)}")
    if size is not None and (len(size) != 2 or min(size) < 16):
        raise InputError(f"size: must be (height, width), both 16 pixels or more, got {size!r}")
    unknown = set(options) - set(PATTERN_OPTIONS.get(pattern or "", ()))
    if unknown:
        known = f"pattern {pattern!r} takes {', '.join(PATTERN_OPTIONS[pattern])}" if pattern else "give the pattern"
        raise InputError(f"options: {', '.join(sorted(unknown))} not understood ({known})")


def make_world_frame(
    seed: int,
    kind: str | None = None,
    pattern: str | None = None,
    size: tuple[int, int] | None = None,
    **options: object,
) -> WorldFrame:
    """One frame of the world (see the module's docstring), deterministic in its arguments.

    Args:
        seed: 0 or more (:func:`world_seed` gives the seeds of a split).
        kind: one of :data:`WORLD_KINDS` (None: either, 50/50).
        pattern: one of :data:`WORLD_PATTERNS` (None: drawn with the kind's odds).
        size: (H, W) (None: :func:`random_size`). What is drawn for None does not depend on the other arguments:
            the frame ``f`` of ``make_world_frame(s)`` is that of ``make_world_frame(s, f.kind, f.pattern, size)``
            with ``size = f.rgb.shape[:2]`` (unless it fell back to points).
        options: the pattern's settings instead of drawn ones (:data:`PATTERN_OPTIONS`: ``beams=16`` for the LiDAR,
            ``count=500`` for points, ``max_range=5.0`` or ``factor=1`` for the depth camera); needs ``pattern``.

    Raises:
        InputError: a negative seed, an unknown kind or pattern, a size under 16 pixels, an option the pattern does not
            take, beams outside 4..256.
    """
    _check(seed, kind, pattern, size, options)
    plan = np.random.default_rng((_TAG, seed))
    u_kind, u_pattern, drawn_size = plan.random(), plan.random(), random_size(plan)
    kind = kind or WORLD_KINDS[int(u_kind >= 0.5)]
    pattern = pattern or WORLD_PATTERNS[int(np.searchsorted(np.cumsum(_ODDS[kind]), u_pattern, side="right"))]
    size = (int(size[0]), int(size[1])) if size is not None else drawn_size
    for attempt in range(_ATTEMPTS):
        frame = _attempt(int(seed), attempt, kind, pattern, size, options)
        if np.count_nonzero(frame.sparse) >= MIN_SPARSE:
            return frame
    frame = _attempt(int(seed), _ATTEMPTS, kind, "points", size, {})  # 50 points or more: every frame has 20 in range
    frame.meta["fallback_from"] = pattern
    return frame
