"""``latency.json``: the run's per-stage times, one output for the whole run (:class:`LatencySink`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from semattnet.inference.sinks.base import OutputSettings, RunSink, Sink, SinkOptions, register_sink

if TYPE_CHECKING:
    from semattnet.inference.timing import StageTimes

__all__ = ["LatencySink"]


@dataclass(frozen=True)
class _Latency(SinkOptions):
    def sinks(self, settings: OutputSettings) -> list[Sink]:
        return [LatencySink(timer=settings.timer)]


@register_sink("latency", option="--stream", options=_Latency)
@dataclass
class LatencySink(RunSink):
    """``latency.json``: the per-stage times of the run (:class:`semattnet.inference.timing.StageTimes`)."""

    timer: StageTimes | None = None
    name: str = "latency.json"
    replays: ClassVar[bool] = False  # the loop adds the kept frames' recorded times to the timer
    once: ClassVar[bool] = True  # rank 0's timer: every rank's frames

    def reads(self) -> frozenset[str]:
        return frozenset()

    def files(self) -> list[str]:
        return [self.name]

    def finish(self, stage: Path) -> None:
        from semattnet._utils.outputs import write_text

        if self.timer is not None:
            write_text(stage / self.name, self.timer.to_json(), overwrite=True)
