"""``--realtime`` never waits a recording's long gap: a gap longer than a few sensor periods (or a minute) is
skipped and counted; ``--speed`` is bounded (a one-line usage error, never an OverflowError)."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest
from click.testing import CliRunner

from semattnet.cli import main
from tests.robotics._faulty_bag import IMAGE_TOPIC, POINTS_TOPIC
from tests.robotics.test_long_runs import write_bag

pytest.importorskip("rosbags")

TOPICS = ["--image-topic", IMAGE_TOPIC, "--points-topic", POINTS_TOPIC]


def test_an_hour_gap_is_skipped_and_counted(tmp_path: Path) -> None:
    """Frames 0.1 s apart with an hour between frames 3 and 4: the replay takes about 0.5 s, not an hour; the gap
    is in the latency table and latency.json."""
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.inference.pipeline import RunOptions, check_frames
    from semattnet.inference.sinks import LatencySink, default_sinks
    from semattnet.inference.timing import StageTimes
    from semattnet.robotics import BagSource

    bag, out = write_bag(tmp_path / "b_mcap", 6, 32, 48, gaps_s={4: 3600.0}), tmp_path / "out"
    source, timer = BagSource(bag, IMAGE_TOPIC, POINTS_TOPIC), StageTimes()
    sinks = [*default_sinks(), LatencySink(timer=timer)]
    plan = check_frames(source, sinks, out, options=RunOptions(realtime=1.0))
    run = threading.Thread(
        target=plan.run, args=(ClassicalCompleter(),), daemon=True, kwargs={"log": lambda _: None, "timer": timer}
    )
    run.start()
    run.join(20)
    assert not run.is_alive(), "--realtime waited the recording's gap"
    assert timer.gaps_skipped == 1 and timer.longest_gap_s == pytest.approx(3600.0)
    assert "--realtime skipped 1 gap(s) between frames too long to wait for" in timer.table()
    assert json.loads((out / "latency.json").read_text())["gaps_skipped"] == 1


def test_pace_keeps_the_recorded_gaps() -> None:
    """Gaps within a few periods are waited as recorded (speed 2: half), a long one replaced by one period."""
    from semattnet.inference.feed import _Pace
    from semattnet.inference.timing import StageTimes

    timer = StageTimes()
    pace = _Pace(2.0, timer)
    start = pace.due
    for t in (0.0, 0.1, 0.2, 0.35, 100.0, 100.1):
        pace.wait_s(t)
    assert pace.due - start == pytest.approx((0.35 + 0.1 + 0.1) / 2)  # the 99.65 s gap counts as one 0.1 s period
    assert (timer.gaps_skipped, timer.longest_gap_s) == (1, pytest.approx(99.65))


@pytest.mark.parametrize("speed", ["1e-9", "0.001"])
def test_speed_out_of_bounds_is_one_line(tmp_path: Path, speed: str) -> None:
    bag = write_bag(tmp_path / "b_mcap", 1, 32, 48)
    res = CliRunner().invoke(
        main,
        [
            "predict",
            "--bag",
            str(bag),
            *TOPICS,
            "--method",
            "classical",
            "--out",
            str(tmp_path / "out"),
            "--realtime",
            "--speed",
            speed,
        ],
    )
    assert res.exit_code == 2 and "--speed" in res.output, res.output
    assert not (tmp_path / "out").exists()
