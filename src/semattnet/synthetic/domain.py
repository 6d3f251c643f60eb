"""The sensor rig and the look of a synthetic domain: LiDAR, camera mounting and intrinsics, light and materials.

A :class:`Domain` says how a scene is seen, not what it holds: the same scene seed gives the same street in
every domain. :data:`SOURCE` is the generator's original rig (KITTI-like: 64 beams from +2 to -24.8 deg, the
camera 1.65 m above the road, level, KITTI's field of view) and draws exactly the numbers it always drew;
:data:`TARGET` is another car's rig, as a robot builder would have: a 32-beam LiDAR mounted lower and
tilted down, a camera lower, pitched down, with a wider lens and a centred principal point, the sun from
other directions, a darker exposure, warmer colours and more image noise. :data:`DOMAINS` names them.

Frames (metres): the *street frame* is the original camera frame of the first frame of a scene (x right,
y down, z forward, the ground plane at ``y = CAM_HEIGHT``); a rig's camera sits ``camera_height`` above
the ground, pitched down by ``camera_pitch``; the LiDAR sits ``lidar_offset`` from the camera (street
axes), pitched down by ``lidar_pitch``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semattnet._errors import InputError

from .layout import CAM_HEIGHT

__all__ = ["DOMAINS", "SOURCE", "TARGET", "Domain", "Pose", "get_domain", "pitch_down"]


@dataclass(frozen=True)
class Domain:
    """How a synthetic scene is sensed and lit (every default is the original generator's).

    Attributes:
        name: a short name (written to the manifests).
        beams: LiDAR beams at full size; images under 300 rows get ``max(beams / 4, beams * rows / 352)``
            beams, so the points per pixel stay about the same at any image size.
        elevation: the top and the bottom beam, degrees above the LiDAR's horizontal (evenly spaced between).
        points_per_column: returns per image column per beam (the azimuth resolution).
        lidar_offset: the LiDAR's position from the camera, street axes (x right, y down, z forward), metres.
        lidar_pitch: the LiDAR tilted down by this many degrees.
        camera_height: the camera above the ground, metres.
        camera_pitch: the camera tilted down by this many degrees.
        focal_scale: focal length as a multiple of KITTI's (at KITTI's field of view for the width).
        principal_row: the principal point's row as a share of the height; None: where KITTI has it.
        sun_x, sun_z: ranges of the sun direction's x and z (its y is 1 before normalising: downwards).
        exposure: range of the frame's exposure.
        albedo_gain: per-channel (RGB) factor on every surface's colour (paint, ground, facades).
        noise: relative image noise (standard deviation).
    """

    name: str = "source"
    beams: int = 64
    elevation: tuple[float, float] = (2.0, -24.8)
    points_per_column: float = 0.46
    lidar_offset: tuple[float, float, float] = (0.0, -0.08, -0.27)
    lidar_pitch: float = 0.0
    camera_height: float = CAM_HEIGHT
    camera_pitch: float = 0.0
    focal_scale: float = 1.0
    principal_row: float | None = None
    sun_x: tuple[float, float] = (-0.6, 0.6)
    sun_z: tuple[float, float] = (-0.3, 0.8)
    exposure: tuple[float, float] = (0.7, 1.15)
    albedo_gain: tuple[float, float, float] = (1.0, 1.0, 1.0)
    noise: float = 0.06

    def __post_init__(self) -> None:
        if not 4 <= self.beams <= 256:
            raise InputError(f"domain {self.name!r}: beams must be 4..256, got {self.beams}")
        if not self.elevation[0] > self.elevation[1]:
            raise InputError(f"domain {self.name!r}: elevation must be (top, bottom) degrees with top > bottom")
        if not 0.3 <= self.camera_height <= 5.0 or not -30.0 <= self.camera_pitch <= 30.0:
            raise InputError(f"domain {self.name!r}: camera_height must be 0.3..5 m and camera_pitch -30..30 deg")
        if self.focal_scale <= 0 or self.noise < 0 or self.exposure[0] > self.exposure[1]:
            raise InputError(f"domain {self.name!r}: focal_scale must be > 0, noise >= 0, exposure (low, high)")

    def n_beams(self, height: int) -> int:
        """Beams for an image of ``height`` rows (all of them from 300 rows up)."""
        return self.beams if height >= 300 else max(self.beams // 4, round(self.beams * height / 352))

    @property
    def level(self) -> bool:
        """The original mounting: camera 1.65 m up, camera and LiDAR level (the fast, original code path)."""
        return self.camera_height == CAM_HEIGHT and self.camera_pitch == 0.0 and self.lidar_pitch == 0.0


#: The original generator's rig and look (KITTI-like); what every shipped model was trained on.
SOURCE = Domain()
#: Another car: a lower, tilted 32-beam LiDAR, a lower camera pitched down with a wider lens, other light.
TARGET = Domain(
    name="target",
    beams=32,
    elevation=(10.0, -30.0),
    lidar_offset=(0.0, -0.05, 0.4),
    lidar_pitch=2.0,
    camera_height=1.3,
    camera_pitch=3.0,
    focal_scale=0.8,
    principal_row=0.5,
    sun_x=(-0.9, 0.9),
    sun_z=(0.2, 1.2),
    exposure=(0.55, 0.95),
    albedo_gain=(1.12, 1.0, 0.82),
    noise=0.08,
)
#: Domains by name.
DOMAINS: dict[str, Domain] = {d.name: d for d in (SOURCE, TARGET)}


def get_domain(domain: str | Domain) -> Domain:
    """A :class:`Domain`, or the one of :data:`DOMAINS` named ``domain``.

    Raises:
        InputError: an unknown name.
    """
    if isinstance(domain, Domain):
        return domain
    if domain not in DOMAINS:
        raise InputError(f"domain: unknown synthetic domain {domain!r}; expected one of {', '.join(DOMAINS)}")
    return DOMAINS[domain]


def pitch_down(degrees: float) -> np.ndarray:
    """(3, 3) rotation (street <- sensor, camera-like axes) of a sensor tilted down by ``degrees``."""
    a = np.deg2rad(degrees)
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


@dataclass(frozen=True)
class Pose:
    """Where a camera (or the LiDAR) is in the street frame: ``p_street = R @ p_sensor + position``."""

    position: np.ndarray  # (3,)
    R: np.ndarray  # (3, 3), street <- sensor (camera-like axes: x right, y down, z forward)

    @property
    def identity(self) -> bool:
        """The original camera's pose (the street frame itself)."""
        return not np.any(self.position) and np.array_equal(self.R, np.eye(3))

    @staticmethod
    def of_camera(domain: Domain, forward: float = 0.0, right: float = 0.0) -> Pose:
        """The camera of ``domain`` after driving ``forward`` metres along the street, moved ``right`` (a baseline)."""
        R = pitch_down(domain.camera_pitch)
        position = np.array([0.0, CAM_HEIGHT - domain.camera_height, forward]) + R @ np.array([right, 0.0, 0.0])
        return Pose(position, R)

    @staticmethod
    def of_lidar(domain: Domain, forward: float = 0.0) -> Pose:
        """The LiDAR of ``domain`` (camera-like axes) after driving ``forward`` metres along the street."""
        cam = np.array([0.0, CAM_HEIGHT - domain.camera_height, forward])
        return Pose(cam + np.asarray(domain.lidar_offset, float), pitch_down(domain.lidar_pitch))
