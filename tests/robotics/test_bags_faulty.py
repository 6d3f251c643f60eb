"""A bad frame of a bag is that frame's fault: every image is a frame, a bad one raises its own one-line
DataError, and the frames after it still load, reading the bag forward once (ROS 1, ROS 2 sqlite3, MCAP)."""

from __future__ import annotations

import contextlib
import struct
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from semattnet._errors import DataError
from semattnet.robotics import BagSource
from semattnet.robotics.bags import BagFailure, BagPair, BagPairs
from semattnet.robotics.bags.pairs import decode_message
from tests.robotics._faulty_bag import FAULTS, FORMATS, GOOD, IMAGE_TOPIC, N_FRAMES, POINTS_TOPIC, write_faulty_bag

pytest.importorskip("rosbags")

NAMES = [f"{i:010d}" for i in range(N_FRAMES)]


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, Path, dict[int, str]]]:
    """Per format: the faulty bag, the clean bag (same frames, none bad) and the bad frames' reasons."""
    root = tmp_path_factory.mktemp("faulty")
    out = {}
    for fmt, name in FORMATS.items():
        faulty = write_faulty_bag(root / name, fmt)
        (root / "clean").mkdir(exist_ok=True)
        clean = write_faulty_bag(root / "clean" / name, fmt, bad=())
        assert clean.bad == {}
        out[fmt] = (faulty.path, clean.path, faulty.bad)
    return out


@pytest.fixture
def opens(monkeypatch: pytest.MonkeyPatch) -> list[Path]:
    """The bags BagPairs' frame pass opens (one entry per pass started)."""
    import semattnet.robotics.bags.pairs as source_module

    real, seen = source_module.open_bag, []

    @contextmanager
    def counting(path: Any) -> Iterator[Any]:
        seen.append(Path(path))
        with real(path) as reader:
            yield reader

    monkeypatch.setattr(source_module, "open_bag", counting)
    return seen


def test_helper_reasons() -> None:
    assert sorted(i for i, _ in FAULTS.values()) == [1, 3, 4, 5, 6]
    assert set(GOOD).isdisjoint(i for i, _ in FAULTS.values())


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_every_image_is_a_frame(bags: dict[str, tuple[Path, Path, dict[int, str]]], fmt: str) -> None:
    path, _, _ = bags[fmt]
    logged: list[str] = []
    source = BagSource(path, IMAGE_TOPIC, POINTS_TOPIC, log=logged.append)
    assert source.names == NAMES and len(source) == N_FRAMES and len(source.stamps_ns) == N_FRAMES
    assert "7 image(s) paired with a scan within 50.0 ms, 1 dropped" in logged[0]
    outcomes = list(BagPairs(path, IMAGE_TOPIC, POINTS_TOPIC))
    assert [o.index for o in outcomes] == list(range(N_FRAMES))
    assert [isinstance(o, BagPair) for o in outcomes] == [True, True, True, False, False, False, False, True]


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_bad_frames_fail_alone_and_the_bag_is_read_once(
    bags: dict[str, tuple[Path, Path, dict[int, str]]], fmt: str, opens: list[Path]
) -> None:
    path, clean_path, bad = bags[fmt]
    source, clean = BagSource(path, IMAGE_TOPIC, POINTS_TOPIC), BagSource(clean_path, IMAGE_TOPIC, POINTS_TOPIC)
    opens.clear()
    for i, name in enumerate(source.names):
        if i in bad:
            with pytest.raises(DataError) as err:
                source.load(name)
            message = str(err.value)
            assert message.startswith(f"{path}: {IMAGE_TOPIC} image {i}: ") and bad[i] in message, message
            assert "\n" not in message
            continue
        got, want = source.load(name), clean.load(name)
        assert got.name == want.name == name
        for key in ("rgb", "sparse", "points", "K"):
            assert np.array_equal(getattr(got, key), getattr(want, key)), (name, key)
        assert got.meta.stamp_ns == want.meta.stamp_ns and np.count_nonzero(got.sparse) > 100
    assert opens == [path, clean_path]  # one forward pass each, through every bad frame
    assert np.array_equal(source.load("0000000002").sparse, clean.load("0000000002").sparse)  # backwards: again


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_check_frame_by_frame(bags: dict[str, tuple[Path, Path, dict[int, str]]], fmt: str, opens: list[Path]) -> None:
    """What the frame loop does: check([name]) per frame in order, then load it; one pass over the bag."""
    path, _, bad = bags[fmt]
    source = BagSource(path, IMAGE_TOPIC, POINTS_TOPIC)
    opens.clear()
    failed_check, failed_load = {}, {}
    for name in source.names:
        try:
            source.check([name])
        except DataError as exc:
            failed_check[int(name)] = str(exc)
        try:
            source.load(name)
        except DataError as exc:
            failed_load[int(name)] = str(exc)
    assert opens == [path]
    empty = FAULTS["empty_scan"][0]  # an empty scan is found by the projection: load, not check (decoding)
    assert set(failed_check) == set(bad) - {empty} and set(failed_load) == set(bad)
    assert all(failed_load[i] == m for i, m in failed_check.items())
    with pytest.raises(DataError, match=r"image 3: no /lidar scan within"):
        source.check(source.names)  # several names: the first bad frame's error


def test_check_behind_a_read_ahead_reads_once(
    bags: dict[str, tuple[Path, Path, dict[int, str]]], opens: list[Path]
) -> None:
    """A reader two frames ahead and check([name]) behind it share one pass (the last few outcomes are kept)."""
    path, _, bad = bags["mcap"]
    source = BagSource(path, IMAGE_TOPIC, POINTS_TOPIC)
    opens.clear()
    failed = {}
    for k, name in enumerate(source.names):
        for ahead in source.names[k : k + 3]:
            with contextlib.suppress(DataError):
                source.read(ahead)
        try:
            source.check([name])
        except DataError as exc:
            failed[k] = str(exc)
    assert opens == [path] and set(failed) == set(bad) - {FAULTS["empty_scan"][0]}


def test_a_broken_bag_is_not_read_again_for_each_later_frame(
    bags: dict[str, tuple[Path, Path, dict[int, str]]], opens: list[Path]
) -> None:
    """A bag-level error mid-pass (a truncated file) fails every later frame without re-reading the bag."""
    _, clean_path, _ = bags["ros1"]
    source = BagSource(clean_path, IMAGE_TOPIC, POINTS_TOPIC)
    pairs = source.pairs

    class Dying:
        image_topic, points_topic = pairs.image_topic, pairs.points_topic

        def __iter__(self) -> Iterator[BagPair | BagFailure]:
            for item in pairs:
                if item.index == 6:
                    raise DataError(f"{clean_path}: cannot read the bag (truncated or corrupt?): boom")
                yield item

    source.pairs = Dying()  # type: ignore[assignment]
    opens.clear()
    source.load("0000000005")
    for name in ("0000000006", "0000000007", "0000000006"):
        with pytest.raises(DataError, match="boom"):
            source.load(name)
    assert len(opens) == 1
    assert source.load("0000000002").name == "0000000002" and len(opens) == 1  # one of the last few: kept
    assert source.load("0000000000").name == "0000000000" and len(opens) == 2  # an earlier frame: read again


def test_an_undeserialisable_message_is_one_line() -> None:
    def bad() -> None:
        raise struct.error("unpack requires a buffer of 4 bytes")

    err = decode_message("BAG: /cam/image image 3", bad)
    assert isinstance(err, DataError)
    assert str(err) == "BAG: /cam/image image 3: cannot deserialise the message: unpack requires a buffer of 4 bytes"
    assert decode_message("x", lambda: 5) == 5
