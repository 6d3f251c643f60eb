"""Every registered output sink (:data:`semattnet.inference.sinks.SINKS`, the robot ones included)
writes two tiny predictions: its outputs exist where it says, decode back to what the prediction holds, and a
bad destination or a prediction it cannot write is refused."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from semattnet._errors import InputError
from semattnet._utils.outputs import bag_mark
from semattnet.data.frames import Frame
from semattnet.data.io import read_depth, read_image
from semattnet.inference.completer import Completion
from semattnet.inference.sinks import SINKS, Prediction, RunSink, Sink, list_sinks, predict_frame
from tests._base import RegistryTester
from tests.registry._trees import SIZE

K = np.array([[50.0, 0, 32], [0, 50.0, 16], [0, 0, 1]])
NAMES = ("f00", "f01")


def prediction(name: str = "f00", uncertainty: bool = True, K: np.ndarray | None = K) -> Prediction:
    """A 32x64 frame (a depth ramp of 2-40 m, a hole row) completed with a ramp uncertainty."""
    rng = np.random.default_rng(int(name[-2:]))
    depth = np.tile(np.linspace(2, 40, SIZE[1], dtype=np.float32), (SIZE[0], 1))
    depth[0] = 0  # a hole
    sparse = np.where(rng.random(SIZE) < 0.1, depth, 0).astype(np.float32)
    frame = Frame(name, rng.integers(0, 256, (*SIZE, 3), dtype=np.uint8), sparse, K=K, gt=depth)
    unc = (0.05 * depth).astype(np.float32) if uncertainty else None
    with pytest.warns(UserWarning, match="1 hole|64 hole"):  # the hole row, said once per frame
        return predict_frame(frame, Completion(depth, uncertainty=unc))


def run(sink: Sink, out: Path, preds: list[Prediction]) -> None:
    """What the frame loop does with a sink: a run sink opened, fed, finished and committed."""
    if isinstance(sink, RunSink):
        sink.open(overwrite=False)
    for pred in preds:
        sink.write(out, pred)
    if isinstance(sink, RunSink):
        sink.finish(out)
        sink.commit()


def _png(path: Path, pred: Prediction) -> None:
    np.testing.assert_array_equal(read_depth(path), pred.stored)


def _color(path: Path, pred: Prediction) -> None:
    from semattnet.viz.depth import colorize_depth

    np.testing.assert_array_equal(read_image(path), colorize_depth(pred.stored))


def _npy(path: Path, pred: Prediction) -> None:
    np.testing.assert_array_equal(np.load(path), pred.depth)


def _ply(path: Path, pred: Prediction) -> None:
    from plyfile import PlyData

    vertex = PlyData.read(str(path))["vertex"]
    cloud = pred.cloud(80.0, 0)
    np.testing.assert_allclose(np.stack([vertex["x"], vertex["y"], vertex["z"]], 1), cloud.xyz, rtol=1e-6)


def _unc_png(path: Path, pred: Prediction) -> None:
    np.testing.assert_array_equal(read_depth(path), pred.uncertainty_stored)


def _unc_npy(path: Path, pred: Prediction) -> None:
    np.testing.assert_array_equal(np.load(path), pred.uncertainty)


def _panel(path: Path, pred: Prediction) -> None:
    image = read_image(path)
    assert image.ndim == 3 and image.shape[0] >= SIZE[0] and image.shape[1] >= SIZE[1]


def _latency(path: Path, pred: Prediction) -> None:
    assert json.loads(path.read_text())["frames"] == len(NAMES)  # the timer's two frames


def _bag(path: Path, pred: Prediction) -> None:
    from semattnet.robotics.bags import open_bag

    with open_bag(path) as reader:
        depth = [
            reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic == "/semattnet/depth_image"
        ]
    assert len(depth) == len(NAMES)
    img = depth[0]
    got = np.frombuffer(np.asarray(img.data, np.uint8).tobytes(), "<f4").reshape(SIZE)
    np.testing.assert_array_equal(np.nan_to_num(got, nan=0.0), pred.stored)  # holes NaN (REP 118)


def _rerun(path: Path, pred: Prediction) -> None:
    from semattnet.robotics.rerun import read_rrd_frames

    frames = read_rrd_frames(path)  # entity -> the sensor times (ns) logged: index x 0.1 s without stamps
    assert frames["world/camera/image/depth"] == [i * 100_000_000 for i in range(len(NAMES))]


def _timer() -> object:
    from semattnet.inference.timing import StageTimes

    timer = StageTimes()
    for name in NAMES:
        timer.add(name, "complete", 0.001)
    return timer


def _stage_is_a_file(sink: Sink, out: Path) -> None:
    """A destination that is a regular file, not a folder."""
    out.write_text("a file")
    run(sink, out, [prediction()])


@dataclass(frozen=True)
class SinkFixture:
    """``make``: the sink writing under a folder; ``outputs``: the files for the frames (relative to it), the
    first one decoded by ``check`` against the first prediction (None: the sink writes no file: the live
    server); ``bad``: a destination or prediction it refuses, with the error and its message."""

    make: Callable[[Path], Sink]
    outputs: Callable[[Path], list[Path]]
    check: Callable[[Path, Prediction], None] | None
    bad: Callable[[Sink, Path], None] = _stage_is_a_file
    error: type[Exception] = OSError
    match: str | None = None
    needs: str | None = None


def per_frame(pattern: str) -> Callable[[Path], list[Path]]:
    return lambda out: [out / pattern.format(name) for name in NAMES]


def _no_uncertainty(sink: Sink, out: Path) -> None:
    run(sink, out, [prediction(uncertainty=False)])


def _no_K(sink: Sink, out: Path) -> None:
    run(sink, out, [prediction(K=None)])


def _bag_sink(out: Path) -> Sink:
    from semattnet.robotics.sinks import BagSink

    return BagSink(target=out / "pred.bag")


def _rerun_sink(out: Path) -> Sink:
    from semattnet.robotics.sinks import RerunSink

    return RerunSink(target=out / "pred.rrd")


def _live_sink(out: Path) -> Sink:
    from semattnet.robotics.live import LiveSink

    return LiveSink(address="127.0.0.1:0")


def _live_bad(sink: Sink, out: Path) -> None:
    run(replace(sink, address="127.0.0.1:99999"), out, [prediction()])  # type: ignore[type-var]


def _make(name: str, **kw: object) -> Callable[[Path], Sink]:
    return lambda out: SINKS[name].cls(**kw)


UNC = "the method gives no per-pixel uncertainty"
FIXTURES = {
    "depth-png": SinkFixture(_make("depth-png"), per_frame("{}.png"), _png),
    "color-png": SinkFixture(_make("color-png"), per_frame("{}_color.png"), _color),
    "npy": SinkFixture(_make("npy"), per_frame("{}.npy"), _npy),
    "ply": SinkFixture(_make("ply"), per_frame("{}.ply"), _ply, _no_K, InputError, "needs the frame's intrinsics K"),
    "uncertainty-png": SinkFixture(
        _make("uncertainty-png"), per_frame("uncertainty/{}.png"), _unc_png, _no_uncertainty, InputError, UNC
    ),
    "uncertainty-npy": SinkFixture(
        _make("uncertainty-npy"), per_frame("uncertainty/{}.npy"), _unc_npy, _no_uncertainty, InputError, UNC
    ),
    "panel": SinkFixture(_make("panel"), per_frame("{}_panel.png"), _panel),
    "latency": SinkFixture(
        lambda out: SINKS["latency"].cls(timer=_timer()), lambda out: [out / "latency.json"], _latency
    ),
    "bag": SinkFixture(
        _bag_sink,
        lambda out: [out / "pred.bag"],
        _bag,
        _no_K,
        InputError,
        "the bag output needs the frame's intrinsics K",
        needs="rosbags",
    ),
    "rerun": SinkFixture(
        _rerun_sink,
        lambda out: [out / "pred.rrd"],
        _rerun,
        _no_K,
        InputError,
        "the Rerun recording needs the frame's intrinsics K",
        needs="rerun",
    ),
    "live": SinkFixture(
        _live_sink, lambda out: [], None, _live_bad, InputError, r"expected \[HOST:\]PORT", needs="foxglove"
    ),
}


class TestSinks(RegistryTester[SinkFixture]):
    kind = "sink"
    fixtures: ClassVar[Mapping[str, SinkFixture]] = FIXTURES

    @classmethod
    def entries(cls) -> list[str]:
        return list_sinks()

    def _sink(self, entry: str, out: Path) -> tuple[SinkFixture, Sink]:
        fx = self.fixture(entry)
        if fx.needs is not None:
            pytest.importorskip(fx.needs)
        out.mkdir(exist_ok=True)
        sink = fx.make(out)
        assert isinstance(sink, SINKS[entry].cls)
        return fx, sink

    def test_smoke(self, entry: str, tmp_path: Path) -> None:
        fx, sink = self._sink(entry, tmp_path / "out")
        run(sink, tmp_path / "out", [prediction(n) for n in NAMES])
        assert all(p.exists() for p in fx.outputs(tmp_path / "out"))

    def test_cardinality(self, entry: str, tmp_path: Path) -> None:
        """Exactly the files it says it writes: per frame (``path``) or per run (``files``, ``targets``)."""
        out = tmp_path / "out"
        fx, sink = self._sink(entry, out)
        run(sink, out, [prediction(n) for n in NAMES])
        said = [out / p for n in NAMES if (p := sink.path(n)) is not None]
        if isinstance(sink, RunSink):
            said += [out / f for f in sink.files()] + [Path(t) for t in sink.targets()]
        written = sorted(p for p in out.rglob("*") if p.is_file() or p.suffix in (".bag", ".rrd"))
        assert sorted(said) == sorted(fx.outputs(out))
        said += [bag_mark(p) for p in said if p.suffix == ".bag"]  # a ROS 1 bag's mark, part of it
        assert {p for p in written if not any(p.is_relative_to(s) for s in said)} == set()

    def test_exception(self, entry: str, tmp_path: Path) -> None:
        fx, sink = self._sink(entry, tmp_path / "out")
        with pytest.raises(fx.error, match=fx.match) as err:
            fx.bad(sink, tmp_path / "out" / "dest")
        assert not isinstance(err.value, InputError) or "\n" not in str(err.value)
        if isinstance(sink, RunSink):
            sink.abort()

    def test_numerics(self, entry: str, tmp_path: Path) -> None:
        """The first output decoded back equals what the prediction holds."""
        fx, sink = self._sink(entry, tmp_path / "out")
        preds = [prediction(n) for n in NAMES]
        run(sink, tmp_path / "out", preds)
        if fx.check is None:  # the live server writes no file (tests/robotics/test_live.py is its client)
            assert fx.outputs(tmp_path / "out") == []
            return
        fx.check(fx.outputs(tmp_path / "out")[0], preds[0])
