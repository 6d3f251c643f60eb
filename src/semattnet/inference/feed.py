"""Frames through a completer with per-stage times, optionally read ahead in a background thread.

:func:`completions` is the inside of the one frame loop (:func:`semattnet.inference.pipeline.complete_frames`
writes what it yields; :meth:`semattnet.inference.DepthCompleter.stream` yields it): each frame is read
(and decoded), projected, given its semantic map (:class:`~.semantic.SemanticMaps`), completed,
and every stage is timed into a :class:`~.timing.StageTimes`. With ``prefetch=N`` the reading, projection and
segmentation of the next frames run in a background thread while the current frame is completed (and the
frame loop writes the previous one in its own, :mod:`~.writer`); at most ``N`` frames are read ahead of the one
the loop holds (a semaphore), so memory stays bounded.

Stages (:data:`~.timing.STAGES`): ``read`` (read and decode), ``projection`` (LiDAR scan into the image),
``segmentation`` (the semantic map, when one is computed), ``network``, ``propagation``, ``writing`` (every sink).

* A source splits ``read`` from ``projection`` by being a :class:`~semattnet.data.frames.TwoStageSource`:
  ``read(name)`` (raw inputs, decoded) and ``assemble(raw)`` (the :class:`~semattnet.data.frames.Frame`, scan
  projected), as :class:`semattnet.robotics.BagSource` does; for other sources ``load`` is timed as ``read``.
* ``network`` vs ``propagation``: a completer that times the stages inside its call
  (:class:`~semattnet.inference.completer.StageTimed`) gets a hook that times them: for a
  :class:`~semattnet.inference.DepthCompleter` on the ``torch`` engine the model's CSPN++ propagation
  (``propagation``, the fused kernel) is timed inside the engine call and ``network`` is the rest of the call
  (padding, backbone, refinement heads, copies). The exported engines (``openvino``, ``onnxruntime``) and the
  classical baseline are not split: their whole call is ``network``.
"""

from __future__ import annotations

import queue
import statistics
import threading
import time
from collections import deque
from collections.abc import Callable, Generator, Iterator, Sequence
from contextlib import AbstractContextManager, closing, contextmanager, nullcontext
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING, TypeVar

from semattnet.data.frames import Dropped, Frame, FrameSource, LiveSource, TwoStageSource
from semattnet.inference.batching import BatchCompleter, complete_group, groups
from semattnet.inference.contract import Completer, Completion, StageTimed
from semattnet.inference.timing import DEFAULT_SENSOR_PERIOD_S, GAP_PERIODS, MAX_WAIT_S, StageTimes

if TYPE_CHECKING:
    from semattnet.inference.semantic import SemanticMaps

_R = TypeVar("_R")

__all__ = [
    "FrameFault",
    "completions",
    "fault_reason",
    "is_frame_fault",
    "live_completions",
    "read_frame",
]


def is_frame_fault(exc: BaseException) -> bool:
    """Whether ``exc``, raised while one frame was read or completed, is that frame's fault (a corrupt or
    missing input, no LiDAR point in the image, an empty sparse map) rather than the run's (a missing
    package, unusable int8 calibration frames, a full disk, a bug): a :class:`~semattnet.DataError` or
    :class:`~semattnet.InputError`."""
    from semattnet._errors import DataError, InputError, MissingDependencyError
    from semattnet.inference.backends.calibration import CalibrationError

    return isinstance(exc, DataError | InputError) and not isinstance(exc, MissingDependencyError | CalibrationError)


@dataclass(frozen=True)
class FrameFault:
    """A frame the loop did not complete: ``status`` ``skipped`` (its fault, ``reason`` the error's line),
    ``dropped`` (``realtime``: a newer frame arrived first) or ``failed`` (the fault that stops the run)."""

    name: str
    status: str
    reason: str


def _input_of(frame: Frame) -> str:
    """The file a completion fault comes from (the sparse map, the scan, the bag), for its line."""
    paths = frame.paths
    return str(paths.get("sparse") or paths.get("scan") or paths.get("bag") or "")


def fault_reason(exc: BaseException) -> str:
    """A frame fault's one line (the error's text, whitespace collapsed; its type when it has none)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def read_frame(source: FrameSource, name: str, semantic: SemanticMaps | None, timer: StageTimes) -> Frame:
    """One frame read (and projected, when the source splits it) and given its semantic map, timed."""
    if isinstance(source, TwoStageSource):
        with timer.time(name, "read"):
            raw = source.read(name)
        with timer.time(name, "projection"):
            frame: Frame = source.assemble(raw)
    else:
        with timer.time(name, "read"):
            frame = source.load(name)
    return _with_semantic(frame, semantic, timer)


def _with_semantic(frame: Frame, semantic: SemanticMaps | None, timer: StageTimes) -> Frame:
    """``frame`` given its semantic map (timed as ``segmentation`` when a segmenter runs) and its stamp noted."""
    if semantic is not None and semantic.needed and semantic.segmenter is not None and frame.semantic is None:
        with timer.time(frame.name, "segmentation"):
            frame = semantic.fill(frame)
    elif semantic is not None:
        frame = semantic.fill(frame)
    timer.stamp(frame.name, frame.timestamp)
    return frame


@dataclass(frozen=True)
class _Failed:
    """A frame whose reading raised its own fault (:func:`is_frame_fault`)."""

    name: str
    error: BaseException


@dataclass(frozen=True)
class _Crash:
    """An error of the run raised in the reader thread, re-raised by the loop."""

    error: BaseException


def _attempt(source: FrameSource, name: str, semantic: SemanticMaps | None, timer: StageTimes) -> Frame | _Failed:
    """:func:`read_frame`, a frame's own fault returned instead of raised."""
    try:
        return read_frame(source, name, semantic, timer)
    except Exception as exc:
        if not is_frame_fault(exc):
            raise
        return _Failed(name, exc)


class _End(Enum):
    """The end of a reader's frames."""

    DONE = 0


_DONE = _End.DONE
#: What a reader hands the loop: a frame, a frame that failed to read, or one that was dropped.
_Item = Frame | _Failed | FrameFault


def _prefetched(
    source: FrameSource, names: Sequence[str], semantic: SemanticMaps | None, timer: StageTimes, depth: int
) -> Generator[Frame | _Failed, None, None]:
    """The frames of ``names`` in order, read in a background thread at most ``depth`` frames ahead."""
    slots, stop = threading.Semaphore(depth), threading.Event()
    items: queue.Queue[Frame | _Failed | BaseException | _End] = queue.Queue()

    def work() -> None:
        try:
            for name in names:
                while not slots.acquire(timeout=0.05):
                    if stop.is_set():
                        return
                if stop.is_set():
                    return
                items.put(_attempt(source, name, semantic, timer))
            items.put(_DONE)
        except BaseException as exc:  # handed to the loop, raised there
            items.put(exc)

    thread = threading.Thread(target=work, name="semattnet-prefetch", daemon=True)
    thread.start()
    try:
        while (item := items.get()) is not _DONE:
            if isinstance(item, BaseException):
                raise item
            slots.release()  # the loop holds this frame now: the reader may start one more
            yield item
    finally:
        stop.set()
        thread.join()


class _Mailbox:
    """What the sensor thread hands the loop: the newest frame (one at most; an untaken older one is dropped
    and noted) and, in order, the notes (faults, drops) that go first."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.frame: Frame | None = None
        self.notes: list[FrameFault | _Failed | _Crash] = []
        self.finished = False
        self.most_held = 0

    def post(self, item: Frame | FrameFault | _Failed | _Crash) -> None:
        with self.cond:
            if isinstance(item, Frame):
                if self.frame is not None:
                    why = f"frame {item.name} arrived while the completer was busy (--realtime keeps the newest)"
                    self.notes.append(FrameFault(self.frame.name, "dropped", why))
                self.frame = item
            else:
                self.notes.append(item)
            self.most_held = max(self.most_held, int(self.frame is not None))  # frames waiting
            self.cond.notify()

    def close(self) -> None:
        with self.cond:
            self.finished = True
            self.cond.notify()

    def take(self) -> Frame | FrameFault | _Failed | _Crash | _End:
        """The next note, else the newest frame, waiting for one; ``_DONE`` when the sensor is done."""
        with self.cond:
            while self.frame is None and not self.notes and not self.finished:
                self.cond.wait()
            if self.notes:
                return self.notes.pop(0)
            frame, self.frame = self.frame, None
            return frame if frame is not None else _DONE


class _Pace:
    """When each frame of a paced replay is due: ``speed`` times its sensor pace, a gap longer than
    :data:`GAP_PERIODS` sensor periods (or a wait over :data:`MAX_WAIT_S`) skipped, counted in ``timer``."""

    def __init__(self, speed: float, timer: StageTimes) -> None:
        self.speed, self.timer = speed, timer
        self.due = time.monotonic()
        self.prev: float | None = None
        self.gaps: deque[float] = deque(maxlen=64)  # the last gaps between frames, seconds

    def wait_s(self, t: float) -> float:
        """Seconds until the frame stamped ``t`` (sensor seconds) is due (0: now)."""
        gap, self.prev = (0.0 if self.prev is None else t - self.prev), t
        period = statistics.median(self.gaps) if self.gaps else 0.0
        if gap / self.speed > MAX_WAIT_S or (self.gaps and gap > GAP_PERIODS * period):
            self.timer.gaps_skipped += 1
            self.timer.longest_gap_s = max(self.timer.longest_gap_s, gap)
            gap = period  # the frame comes one period after the one before
        elif gap > 0:
            self.gaps.append(gap)
        self.due += gap / self.speed
        return max(0.0, self.due - time.monotonic())


def _paced(
    source: FrameSource, names: Sequence[str], semantic: SemanticMaps | None, timer: StageTimes, speed: float
) -> Generator[_Item, None, None]:
    """The frames at their sensor pace (``timestamp``, else :data:`~.timing.DEFAULT_SENSOR_PERIOD_S` apart, ``speed``
    times faster; long gaps skipped, :class:`_Pace`): a thread reads each frame and hands it over at its time;
    when the loop is still busy the newest frame wins and the older one is dropped (a ``dropped``
    :class:`FrameFault`). Bounded: one frame waiting, one being read, one being completed."""
    box, stop = _Mailbox(), threading.Event()

    def work() -> None:
        pace = _Pace(speed, timer)
        try:
            for i, name in enumerate(names):
                item = _attempt(source, name, semantic, timer)
                if isinstance(item, Frame):
                    t = item.timestamp if item.timestamp is not None else i * DEFAULT_SENSOR_PERIOD_S
                    if stop.wait(pace.wait_s(t)):
                        return
                box.post(item)
        except BaseException as exc:
            box.post(_Crash(exc))
        finally:
            box.close()

    thread = threading.Thread(target=work, name="semattnet-sensor", daemon=True)
    thread.start()
    try:
        while (item := box.take()) is not _DONE:
            if isinstance(item, _Crash):
                raise item.error
            yield item
    finally:
        stop.set()
        thread.join()
        timer.queue_most = box.most_held


@contextmanager
def _inner_stages(completer: Completer, timer: StageTimes, current: list[str]) -> Iterator[None]:
    """While active, the stages a :class:`StageTimed` completer runs inside its call (a ``torch``-engine
    :class:`DepthCompleter`'s ``propagation``) are timed as such, for the frame the loop completes."""
    if not isinstance(completer, StageTimed):
        timer.notes.setdefault("propagation", "the method has none")
        yield
        return
    thread = threading.get_ident()

    def hook(stage: str) -> AbstractContextManager[object]:
        return timer.time(current[0], stage) if threading.get_ident() == thread else nullcontext()

    with completer.timing(hook) as stages:
        if "propagation" not in stages:
            timer.notes.setdefault("propagation", "not split from network by this engine")
        yield


def _frames(
    source: FrameSource,
    names: Sequence[str],
    semantic: SemanticMaps | None,
    timer: StageTimes,
    prefetch: int,
    realtime: float | None,
) -> Generator[_Item, None, None]:
    """The reader the options ask for: paced (``realtime``), read ahead (``prefetch``) or in line."""
    if realtime is not None:
        return _paced(source, names, semantic, timer, realtime)
    if prefetch > 0:
        return _prefetched(source, names, semantic, timer, prefetch)
    return (_attempt(source, name, semantic, timer) for name in names)


def _complete_one(
    completer: Completer,
    group: Sequence[Frame],
    timer: StageTimes,
    current: list[str],
    fault: Callable[[Frame, Exception], None],
) -> Iterator[tuple[Frame, Completion]]:
    """The one frame of ``group`` through ``completer``, timed as ``network`` (``fault`` gets what it raised)."""
    frame = group[0]
    current[0] = frame.name
    try:
        with timer.time(frame.name, "network"):
            completion = completer(frame.rgb, frame.sparse, frame.semantic)
    except Exception as exc:
        fault(frame, exc)
        return
    yield frame, completion


def _start_timer(timer: StageTimes | None, reader: str) -> StageTimes:
    """``timer`` (a new one when None) set for a run whose reading runs in ``reader``'s thread ("": in line)."""
    timer = timer if timer is not None else StageTimes()
    timer.overlapped = bool(reader)
    if reader:
        timer.beside.update(dict.fromkeys(("read", "projection", "segmentation"), f"the {reader} thread"))
    timer.notes.setdefault("segmentation", "no segmenter run")
    timer.notes.setdefault("projection", "inside read/decode (the source does not split it)")
    return timer


@dataclass
class _FaultRule:
    """What :func:`completions` does with a frame's fault: reported as a :class:`FrameFault` (``failed`` when it
    stops the run, else ``skipped``), then raised (``stop_on_fault``, or no ``report``) with the input named."""

    timer: StageTimes
    report: Callable[[FrameFault], None] | None
    stop_on_fault: bool

    def __call__(self, name: str, exc: BaseException, where: str = "") -> None:
        self.timer.discard(name)
        reason = fault_reason(exc)
        reason = f"{where}: {reason}" if where and where not in reason else reason
        if self.report is not None:
            self.report(FrameFault(name, "failed" if self.stop_on_fault else "skipped", reason))
        if self.stop_on_fault or self.report is None:
            if reason != fault_reason(exc):  # the file named: the same error, with where it comes from
                from semattnet._errors import DataError

                raise DataError(reason) from exc
            raise exc

    def of_input(self, name: str, exc: Exception, where: str = "") -> None:
        """``exc``, raised reading or completing frame ``name``: the frame's fault (:func:`is_frame_fault`), else
        raised as it is."""
        if not is_frame_fault(exc):
            raise exc
        self(name, exc, where)

    def of_frame(self, frame: Frame, exc: Exception) -> None:
        """A fault completing ``frame``, its input named (anything else raised as it is)."""
        self.of_input(frame.name, exc, _input_of(frame))


def completions(
    source: FrameSource,
    completer: Completer,
    names: Sequence[str] | None = None,
    semantic: SemanticMaps | None = None,
    timer: StageTimes | None = None,
    prefetch: int = 0,
    *,
    report: Callable[[FrameFault], None] | None = None,
    stop_on_fault: bool = True,
    realtime: float | None = None,
    batch_size: int = 1,
) -> Iterator[tuple[Frame, Completion]]:
    """``(frame, completion)`` for each of ``names`` (default: all of ``source``), in order, every stage timed
    into ``timer``; ``prefetch`` > 0 reads that many frames ahead in a background thread (module doc).
    ``semantic``: a bound :class:`~.semantic.SemanticMaps` (None: frames as the source gives them).
    The time between yields (what the caller does with a frame, e.g. writing) counts in the wall time.

    A frame's own fault (:func:`is_frame_fault`, raised reading or completing it) goes to ``report`` as a
    :class:`FrameFault` and the loop goes on, or (``stop_on_fault``, or no ``report``) is raised after a
    ``failed`` report. ``realtime``: replay at the frames' sensor pace, that many times faster (1.0: as
    recorded); frames that arrive while the completer is busy are dropped (reported ``dropped``). ``batch_size``:
    frames of one size per engine call (:mod:`~semattnet.inference.batching`; not with ``realtime``)."""
    timer = _start_timer(timer, "sensor" if realtime is not None else "reader" if prefetch > 0 else "")
    names = list(source.names if names is None else names)
    current = [""]
    fault = _FaultRule(timer, report, stop_on_fault)
    batched = batch_size > 1 and realtime is None
    try:
        frames = _frames(source, names, semantic, timer, prefetch, realtime)
        with closing(frames), _inner_stages(completer, timer, current):
            timer.begin()  # after the engine is built; the reader starts with the first frame
            for group in groups(frames, batch_size if batched else 1):
                item = group[0]
                if isinstance(item, FrameFault):  # dropped by the pace
                    timer.discard(item.name)
                    if report is not None:
                        report(item)
                    continue
                if isinstance(item, _Failed):
                    fault(item.name, item.error)
                    continue
                batch = [f for f in group if isinstance(f, Frame)]
                if batched and isinstance(completer, BatchCompleter):
                    yield from complete_group(completer, batch, timer, current, fault.of_frame)
                else:
                    yield from _complete_one(completer, batch, timer, current, fault.of_frame)
    finally:
        timer.end()


def live_completions(
    source: LiveSource[_R],
    completer: Completer,
    stop: threading.Event,
    timer: StageTimes,
    *,
    semantic: SemanticMaps | None = None,
    report: Callable[[FrameFault], None] | None = None,
    frames: int | None = None,
    tick: Callable[[], None] | None = None,
) -> Iterator[tuple[Frame, Completion]]:
    """:func:`completions` for frames a sensor pushes (:class:`~semattnet.data.frames.LiveSource`): until ``stop``
    is set (or ``frames`` frames were completed or skipped), the newest item is taken, assembled (timed as
    ``projection``), given its semantic map and completed; an item replaced before it was taken goes to ``report``
    as ``dropped``, the way ``--realtime`` drops frames. A frame's own fault (:func:`is_frame_fault`) goes to
    ``report`` as ``skipped`` and the loop goes on; any other error ends it. ``tick`` runs between items (a report
    line's clock)."""
    fault = _FaultRule(timer, report, stop_on_fault=False)
    timer = _start_timer(timer, "")
    current, done = [""], 0
    with _inner_stages(completer, timer, current):
        timer.begin()
        try:
            while not stop.is_set() and (frames is None or done < frames):
                item = source.take(0.1)
                if tick is not None:
                    tick()
                if item is None:
                    continue
                if isinstance(item, Dropped):
                    if report is not None:
                        report(FrameFault(item.name, "dropped", item.reason))
                    continue
                done += 1
                name = source.name(item)
                try:
                    with timer.time(name, "projection"):
                        frame = source.assemble(item)
                    frame = _with_semantic(frame, semantic, timer)
                except Exception as exc:
                    fault.of_input(name, exc)
                    continue
                yield from _complete_one(completer, [frame], timer, current, fault.of_frame)
        finally:
            timer.end()
