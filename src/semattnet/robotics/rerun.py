"""Rerun recordings of completed frames (``rerun-sdk``, extra ``rerun``).

Per frame, on one timeline (``sensor_time``) stamped with the sensor time, in the LiDAR frame ``world``
(``FLU``, x forward, y left, z up)::

    world/camera                  Transform3D: the camera pose T_lidar_cam
    world/camera/image            Pinhole: K, image size (camera axes RDF: x right, y down, z forward)
    world/camera/image/rgb        Image
    world/camera/image/sparse     DepthImage, metres (meter = 1), the projected LiDAR input
    world/camera/image/depth      DepthImage, metres, the completed depth
    world/camera/image/semantic   SegmentationImage of Cityscapes trainIds (AnnotationContext: class labels)
    world/lidar/points            Points3D, the scan
    world/completed/points        Points3D, the completed depth back-projected with its colours
    uncertainty                   DepthImage, metres, the per-pixel uncertainty of the completed depth (when
                                  given; outside the camera so that the 3D view does not back-project it)

A file recording is written to a hidden temporary file beside the target and moved into place at
:meth:`RerunLogger.close`; after an error inside the ``with`` block nothing is left. ``serve=True`` streams
the frames live instead of (or besides) the file: a gRPC server that ``rerun GRPC_URL`` connects to, reached
on ``host`` (127.0.0.1 by default) through a :class:`~semattnet.robotics.gate.Gate` (a connection cap,
handshake timeouts, every viewer dropped at :meth:`RerunLogger.close`), and, with a ``web_port``, the web
viewer that ships in the ``rerun-sdk`` wheel (:attr:`RerunLogger.url`; rerun binds it to every interface, so
it is off by default).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from types import ModuleType, TracebackType
from typing import Protocol
from urllib.parse import quote, urlparse

import numpy as np

from semattnet._errors import InputError
from semattnet._utils.atomic import new_file_mode
from semattnet._utils.extras import optional, require
from semattnet.geometry import PointCloud, depth_to_points, invert_T
from semattnet.palette import IGNORE_ID, TRAIN_CLASSES, UNKNOWN_COLOR, colors_to_ids
from semattnet.robotics.gate import Gate

__all__ = ["ENTITIES", "TIMELINE", "RerunLogger", "read_rrd_frames"]

#: The timeline every frame is logged on (sensor time, ns since the epoch).
TIMELINE = "sensor_time"
#: Entity paths by role (module doc).
ENTITIES = {
    "camera": "world/camera",
    "pinhole": "world/camera/image",
    "rgb": "world/camera/image/rgb",
    "sparse": "world/camera/image/sparse",
    "depth": "world/camera/image/depth",
    "semantic": "world/camera/image/semantic",
    "points": "world/lidar/points",
    "cloud": "world/completed/points",
    "uncertainty": "uncertainty",
}


def _rerun() -> ModuleType:
    return require("rerun", "writing a Rerun recording")


class RerunLogger:
    """Log frames to a ``.rrd`` file (``path``), a spawned viewer (``spawn``) and/or a served web viewer
    (``serve``), in any combination.

    Args:
        path: the recording to write (staged, see the module doc); None: no file.
        spawn: start a Rerun viewer and stream to it as well.
        overwrite: replace an existing ``path`` (else :class:`FileExistsError` at once).
        max_depth: completed-cloud points deeper than this are left out, metres (None: all).
        serve: host a gRPC server (the recording, buffered in memory up to 1 GiB for late viewers) on ``host``
            (through the gate, module doc); ``rerun`` :attr:`grpc_url` opens it in a native viewer. The viewers
            are dropped and the gRPC server stops at :meth:`close`.
        grpc_port: the gRPC server's port (Rerun's default 9876; 0: a free port).
        web_port: with ``serve``, also serve the web viewer shipped in the ``rerun-sdk`` wheel (no internet
            needed) on this port (0: a free port); open :attr:`url` in a browser. Its HTTP server (which serves
            only the viewer's files) listens on **every interface** and stays up until the process exits (rerun
            gives no handle to bind or stop it). None (the default): no web viewer.
        host: the interface the gRPC server listens on.

    Attributes:
        url: the web viewer connected to the stream (``http://HOST:WEB_PORT/?url=...``), None without ``serve``.
        grpc_url: the stream (``rerun+http://HOST:GRPC_PORT/proxy``: ``rerun GRPC_URL`` connects a native
            viewer), None without ``serve``.
    """

    def __init__(
        self,
        path: str | os.PathLike[str] | None = None,
        spawn: bool = False,
        overwrite: bool = False,
        app_id: str = "semattnet",
        max_depth: float | None = None,
        serve: bool = False,
        grpc_port: int = 9876,
        web_port: int | None = None,
        host: str = "127.0.0.1",
    ) -> None:
        if path is None and not spawn and not serve:
            raise InputError("RerunLogger: give a .rrd path, spawn=True, serve=True, or several")
        self.path = None if path is None else Path(path)
        if self.path is not None and self.path.exists() and not overwrite:
            raise FileExistsError(f"{self.path} exists; refusing to overwrite (pass --overwrite / overwrite=True)")
        rr = _rerun()
        self.max_depth, self.frames = max_depth, 0
        self.url: str | None = None
        self.grpc_url: str | None = None
        self.rec = rr.RecordingStream(app_id)
        self._tmp: Path | None = None
        self._gate: Gate | None = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.p{os.getpid()}.", suffix=".rrd", dir=self.path.parent)
            os.close(fd)
            self._tmp = Path(tmp)
        try:
            self._set_sinks(rr, spawn, serve, host, grpc_port, web_port)
        except BaseException:
            self._finish(ok=False)
            raise
        self._log_static(rr)

    def _set_sinks(
        self, rr: ModuleType, spawn: bool, serve: bool, host: str, grpc_port: int, web_port: int | None
    ) -> None:
        """The file, the spawned viewer and the served stream + web viewer, as asked."""
        if spawn:
            self.rec.spawn(connect=self._tmp is None and not serve)
        if not serve:
            if spawn and self._tmp is not None:
                self.rec.set_sinks(rr.FileSink(str(self._tmp)), rr.GrpcSink())
            elif self._tmp is not None:
                self.rec.save(str(self._tmp))
            return
        if web_port is not None:
            web_port = _port("0.0.0.0", web_port, "the web viewer")  # rerun's HTTP server binds every interface
        server = rr.GrpcServerSink("127.0.0.1", _port("127.0.0.1", 0, "the gRPC stream"))  # behind the gate
        self._gate = Gate(host, grpc_port, ("127.0.0.1", int(urlparse(str(server.uri)).port or 0)))
        try:
            self._gate.start()
        except OSError as e:
            reason = e.strerror or e
            raise InputError(f"RerunLogger: cannot serve the gRPC stream on {host}:{grpc_port} ({reason})") from None
        sinks = [rr.FileSink(str(self._tmp))] * (self._tmp is not None) + [rr.GrpcSink()] * spawn + [server]
        self.rec.set_sinks(*sinks)
        self.grpc_url = f"rerun+http://{_url_host(host)}:{self._gate.port}/proxy"
        if web_port is None:
            return
        try:
            rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=self.grpc_url)
        except (RuntimeError, OSError) as e:
            raise InputError(f"RerunLogger: cannot serve the web viewer on {web_port} ({_first_line(e)})") from None
        self.url = f"http://{_url_host(host)}:{web_port}/?url={quote(self.grpc_url, safe='')}"

    def _log_static(self, rr: ModuleType) -> None:
        self.rec.log("world", rr.ViewCoordinates.FLU, static=True)
        labels = [rr.AnnotationInfo(id=i, label=name, color=c) for i, (name, c) in enumerate(TRAIN_CLASSES)]
        labels.append(rr.AnnotationInfo(id=IGNORE_ID, label="unknown", color=UNKNOWN_COLOR))
        self.rec.log(ENTITIES["semantic"], rr.AnnotationContext(labels), static=True)

    def __enter__(self) -> RerunLogger:
        return self

    def log_frame(
        self,
        stamp_ns: int,
        rgb: np.ndarray,
        K: np.ndarray,
        T_cam_lidar: np.ndarray,
        *,
        sparse: np.ndarray | None = None,
        depth: np.ndarray | None = None,
        semantic: np.ndarray | None = None,
        points: np.ndarray | None = None,
        uncertainty: np.ndarray | None = None,
        keep: np.ndarray | None = None,
        cloud: PointCloud | None = None,
    ) -> None:
        """One frame at sensor time ``stamp_ns``: ``rgb`` (H, W, 3) uint8, ``K`` (3, 3), ``T_cam_lidar`` (4, 4);
        optional ``sparse`` / ``depth`` / ``uncertainty`` (H, W) metres (0 = none), ``semantic`` (H, W) trainIds
        or (H, W, 3) palette colours, ``points`` (N, 3|4) LiDAR frame; ``keep`` (H, W) bool: the pixels of
        ``depth`` the completed cloud keeps (default all); ``cloud``: that cloud in the camera frame, already
        built (:class:`~semattnet.robotics.frame.RobotFrame`'s; default: ``depth`` back-projected here)."""
        rr = _rerun()
        rgb = np.asarray(rgb, dtype=np.uint8)
        h, w = rgb.shape[:2]
        K = np.asarray(K, dtype=np.float64)
        T_lidar_cam = invert_T(np.asarray(T_cam_lidar, dtype=np.float64))
        log = self.rec.log
        self.rec.set_time(TIMELINE, timestamp=np.datetime64(int(stamp_ns), "ns"))
        log(ENTITIES["camera"], rr.Transform3D(translation=T_lidar_cam[:3, 3], mat3x3=T_lidar_cam[:3, :3]))
        log(ENTITIES["pinhole"], rr.Pinhole(image_from_camera=K, resolution=[w, h], camera_xyz=rr.ViewCoordinates.RDF))
        log(ENTITIES["rgb"], rr.Image(rgb))
        if sparse is not None:
            log(ENTITIES["sparse"], rr.DepthImage(np.asarray(sparse, dtype=np.float32), meter=1.0))
        if semantic is not None:
            sem = np.asarray(semantic)
            ids = colors_to_ids(sem, source="semantic map") if sem.ndim == 3 else sem.astype(np.uint8)
            log(ENTITIES["semantic"], rr.SegmentationImage(ids))
        if points is not None:
            pts = np.asarray(points)[:, :3]
            log(ENTITIES["points"], rr.Points3D(pts[np.isfinite(pts).all(1)]))
        if depth is not None:
            d = np.nan_to_num(np.asarray(depth, dtype=np.float32), nan=0.0)
            log(ENTITIES["depth"], rr.DepthImage(d, meter=1.0))
            if cloud is None:
                cloud = depth_to_points(d, K, rgb=rgb, max_depth=self.max_depth, mask=keep)
            in_lidar = cloud.transform(T_lidar_cam, "lidar")
            log(ENTITIES["cloud"], rr.Points3D(in_lidar.xyz, colors=in_lidar.rgb))
        if uncertainty is not None:
            log(ENTITIES["uncertainty"], rr.DepthImage(np.nan_to_num(np.asarray(uncertainty, np.float32)), meter=1.0))
        self.frames += 1

    def finish_file(self) -> None:
        """Complete the file recording and move it into place while a served stream goes on serving (until
        :meth:`close`); without ``serve``: :meth:`close`."""
        finalize = getattr(optional("rerun_bindings"), "finalize_deferred_sinks", None)  # not in older releases
        if self.rec is None or self._tmp is None or self.path is None:
            return
        if self._gate is None or finalize is None:
            self.close()
            return
        _flush(self.rec, self._tmp)
        finalize(recording=self.rec.to_native())  # the file's sink only: the stream stays
        os.chmod(self._tmp, new_file_mode())
        os.replace(self._tmp, self.path)
        self._tmp = None

    def close(self) -> None:
        """Flush and finish; a file recording is moved into place; the served stream stops (its viewers dropped)."""
        self._finish(ok=True)

    def _finish(self, ok: bool) -> None:
        rec, self.rec = self.rec, None
        if rec is None:
            return
        try:
            _flush(rec, self._tmp)
            if self._gate is not None:  # the viewers dropped first: nothing they do delays the stop
                self._gate.close()
            rec.disconnect()
            if ok and self._tmp is not None and self.path is not None:
                os.chmod(self._tmp, new_file_mode())
                os.replace(self._tmp, self.path)
        finally:
            if self._tmp is not None and self._tmp.exists():
                self._tmp.unlink()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._finish(ok=exc_type is None)


class _Flushes(Protocol):
    def flush(self, *, timeout_sec: float) -> None: ...


def _flush(rec: _Flushes, file: Path | None) -> None:
    """``rec.flush()``, waited for in steps: Rerun's file writer that died on a full disk never finishes a flush
    (it would wait forever), so a timed-out step on a file system with no space left is a full disk."""
    from semattnet._utils.atomic import no_space_left

    while True:
        try:
            rec.flush(timeout_sec=5.0)
            return
        except RuntimeError as exc:
            if "timed out" not in str(exc):
                raise
            if file is not None and no_space_left(file):
                import errno

                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)) from None


def _port(host: str, port: int, what: str) -> int:
    """``port``, checked free on ``host`` (rerun's gRPC server only logs a port in use), or a free one for 0."""
    import socket

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family) as s:
        try:
            s.bind((host, int(port)))
        except OSError as e:
            raise InputError(f"RerunLogger: cannot serve {what} on {host}:{port} ({e.strerror or e})") from None
        return int(s.getsockname()[1])


def _url_host(host: str) -> str:
    """The host to put in a URL: a wildcard address as 127.0.0.1 (this machine), IPv6 in brackets."""
    host = "127.0.0.1" if host in ("0.0.0.0", "") else "[::1]" if host == "::" else host
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


def _first_line(e: BaseException) -> str:
    return (str(e).splitlines() or [type(e).__name__])[0]


def read_rrd_frames(path: str | os.PathLike[str]) -> dict[str, list[int]]:
    """Entity path (without the leading ``/``) -> the sorted sensor times (ns) it was logged at, of a ``.rrd``
    file; static-only entities map to an empty list. (For checking a recording; needs ``rerun-sdk``.)"""
    chunk = require("rerun.chunk", "reading a Rerun recording")
    store = chunk.RrdReader(str(path)).store()
    out: dict[str, list[int]] = {}
    for ch in store.stream():
        entity = str(ch.entity_path).lstrip("/")
        if entity.startswith("__"):
            continue
        times = out.setdefault(entity, [])
        batch = ch.to_record_batch()
        if TIMELINE in batch.schema.names:
            col = batch.column(TIMELINE).cast("int64")
            times.extend(int(v) for v in col.to_pylist() if v is not None)
    return {k: sorted(v) for k, v in out.items()}
