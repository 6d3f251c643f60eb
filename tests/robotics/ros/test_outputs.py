"""The node's outputs: the float depth, the decimated cloud from cached rays, the outputs chosen, a latched
CameraInfo."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from semattnet._errors import InputError
from semattnet.geometry import depth_to_points
from semattnet.inference.contract import Completion
from semattnet.robotics.frame import cloud_rays, strided_cloud
from semattnet.robotics.ros.node import DepthNode
from semattnet.robotics.ros.publish import gives_uncertainty, output_roles
from semattnet.robotics.ros.transport import LATCHED_QOS, OUTPUT_QOS

from ._fakes import INFO, FakeTransport, K, camera_info, image, scan, tf_static

pytest.importorskip("rosbags")

T0 = 1_700_000_000_000_000_000
OUT = "/semattnet/output"


def _fine(rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
    """Depths that the PNG's 1/256 m steps cannot hold; an uncertainty."""
    rng = np.random.default_rng(3)
    depth = rng.uniform(0.5, 80.0, sparse.shape).astype(np.float32)
    depth[0, 0] = 0
    return Completion(depth, uncertainty=np.full(sparse.shape, 0.123456, np.float32))


def _run(completer: object, **kw: object) -> FakeTransport:
    fake = FakeTransport()
    node = DepthNode(fake, completer, say=[].append, **kw).start()  # type: ignore[arg-type]
    fake.deliver("/semattnet/input/camera_info", camera_info())
    fake.deliver("/tf_static", tf_static())
    fake.deliver("/semattnet/input/image", image(T0))
    fake.deliver("/semattnet/input/point_cloud", scan(T0))
    stop = threading.Event()
    threading.Timer(5.0, stop.set).start()
    node.spin(stop, frames=1)
    stop.set()
    return fake


def test_published_depth_is_the_float_prediction_bit_for_bit() -> None:
    """The 32FC1 depth is the completion's float32 (NaN holes), not the PNG's 1/256 m steps; the uncertainty too."""
    fake = _run(_fine)
    want = _fine(np.zeros(0), np.ones((INFO.height, INFO.width)))
    (msg,) = fake.published[f"{OUT}/depth_image"]
    got = np.frombuffer(msg.data.tobytes(), "<f4").reshape(INFO.height, INFO.width)  # type: ignore[attr-defined]
    expect = np.where(want.depth > 0, want.depth, np.nan).astype(np.float32)
    assert got.tobytes() == expect.tobytes()
    assert not np.array_equal(np.round(got[1:] * 256) / 256, got[1:])  # not quantised
    (unc,) = fake.published[f"{OUT}/uncertainty"]  # advertised on the first frame that has one
    u = np.frombuffer(unc.data.tobytes(), "<f4").reshape(INFO.height, INFO.width)  # type: ignore[attr-defined]
    assert u[3, 3] == np.float32(0.123456)


def test_outputs_chosen_and_camera_info_latched() -> None:
    fake = _run(_fine, publish=output_roles(["depth_image", "camera_info"]), latch_camera_info=True)
    assert sorted(t for t in fake.published if t.startswith(OUT)) == [f"{OUT}/camera_info", f"{OUT}/depth_image"]
    assert fake.qos[f"{OUT}/camera_info"] == LATCHED_QOS and LATCHED_QOS.durable and LATCHED_QOS.depth == 1
    assert fake.qos[f"{OUT}/depth_image"] == OUTPUT_QOS
    with pytest.raises(InputError, match="--publish 'depth,cloud': expected one or more of depth_image"):
        output_roles(["depth", "cloud"])


def test_uncertainty_not_advertised_when_the_completer_gives_none() -> None:
    class NoUncertainty:
        compute_uncertainty = False

        def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: object = None) -> Completion:
            return Completion(np.full(sparse.shape, 5.0, np.float32))

    assert gives_uncertainty(NoUncertainty()) is False and gives_uncertainty(_fine) is None
    fake = _run(NoUncertainty())
    assert f"{OUT}/uncertainty" not in fake.published and len(fake.published[f"{OUT}/depth_image"]) == 1


@pytest.mark.parametrize("stride", [1, 3, 4])
def test_strided_cloud_is_every_nth_pixel_of_the_full_one(stride: int) -> None:
    """The cloud from cached rays equals depth_to_points' at every stride-th pixel (float rounding)."""
    rng = np.random.default_rng(0)
    h, w = 13, 17
    Ks = K.copy()
    Ks[0, 1] = 0.5  # skew honoured
    depth = rng.uniform(1, 30, (h, w)).astype(np.float32)
    depth[rng.random((h, w)) < 0.2] = np.nan
    rgb = rng.integers(0, 255, (h, w, 3), np.uint8)
    grid = np.zeros((h, w), bool)
    grid[::stride, ::stride] = True
    keep = rng.random((h, w)) < 0.8
    full = depth_to_points(np.nan_to_num(depth), Ks, rgb=rgb, mask=grid & keep, max_depth=25.0)
    got = strided_cloud(depth, Ks, stride, rgb, keep, 25.0)
    np.testing.assert_allclose(got.xyz, full.xyz, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(got.rgb, full.rgb)  # type: ignore[arg-type]
    assert cloud_rays(Ks, h, w, stride) is cloud_rays(Ks.copy(), h, w, stride)  # cached per (K, size, stride)


def test_a_node_spun_again_publishes_again() -> None:
    """The loop closes its sinks at the end of each spin; the publisher is muted only by an abandoned stop."""
    fake = FakeTransport()
    node = DepthNode(fake, _fine, say=[].append).start()
    fake.deliver("/semattnet/input/camera_info", camera_info())
    fake.deliver("/tf_static", tf_static())
    for k in range(2):
        fake.deliver("/semattnet/input/point_cloud", scan(T0 + k))
        fake.deliver("/semattnet/input/image", image(T0 + k))
        stop = threading.Event()
        threading.Timer(5.0, stop.set).start()
        node.spin(stop, frames=k + 1)
        stop.set()
    assert len(fake.published[f"{OUT}/depth_image"]) == 2
    node.abandon()
    assert node.publisher.muted
