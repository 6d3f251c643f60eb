"""The interactive viewer: one HTML page per report folder to explore completed frames.

:func:`write_viewer` writes into a folder:

- ``viewer.html``: the page. Hovering over the image lists the depth of every method, the
  LiDAR input and the ground truth at that pixel (and the fusion weights); radio buttons pick the
  layer shown (RGB, semantics, LiDAR, the colour-/semantic-/depth-guided depths, fusion weights,
  fused and refined depth, each method's depth and error map, the per-pixel uncertainty when the
  completion has one); a Plotly 3D view shows the
  predicted depth back-projected with the camera intrinsics next to the LiDAR points.
- ``plotly.min.js``: Plotly's JavaScript from the ``plotly`` Python package, once per folder
  (no CDN: the page works offline from ``file://``).
- ``viewer/NNN.js``: one file per frame, loaded when the frame is selected. Pictures are PNG
  data URIs; the values read on hover are zlib-compressed little-endian arrays in base64
  (depths as uint16 centimetres, weights as uint8 / 255); the point clouds are int16
  centimetres in the camera frame (x right, y down, z forward), subsampled on a pixel grid
  (:func:`cloud_stride`, :func:`cloud_points`).

:func:`write_prediction_report` builds the page from what ``semattnet predict`` wrote.
"""

from __future__ import annotations

import base64
import io
import json
import math
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from string import Template
from typing import TYPE_CHECKING

import numpy as np

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path
from semattnet.geometry.cameras import parse_intrinsics

if TYPE_CHECKING:
    from semattnet.data.pairing import FramePaths
    from semattnet.geometry import PointCloud

__all__ = [
    "ViewerFrame",
    "cloud_points",
    "cloud_stride",
    "parse_intrinsics",
    "write_prediction_report",
    "write_viewer",
]

#: Points of the predicted cloud per frame, at most (a pixel grid; see :func:`cloud_stride`).
MAX_POINTS = 12000

#: (output key, label) of a model's intermediate depths and fusion weights.
_DEPTHS = (
    ("color_depth", "Colour-guided depth"),
    ("semantic_depth", "Semantic-guided depth"),
    ("guided_depth", "Depth-guided depth"),
    ("fused_depth", "Fused depth"),
    ("refined_depth", "Refined depth"),
)
_WEIGHTS = (
    ("color_conf", "Colour-guided weight"),
    ("semantic_conf", "Semantic-guided weight"),
    ("guided_conf", "Depth-guided weight"),
)


@dataclass
class ViewerFrame:
    """One frame of the viewer.

    ``depths``: method -> completed depth (H, W) metres, 0 = none; ``outputs``: the intermediate
    arrays of ``outputs_of`` (keys as :class:`~semattnet.inference.completer.Completion` has
    them); ``K``: (3, 3) intrinsics (no 3D view without them); ``cloud_of``: the method whose
    depth becomes the point cloud (default: the last of ``depths``); ``uncertainty``: (H, W) metres, the
    per-pixel uncertainty of that depth (0 = none; default ``outputs["uncertainty"]`` when present), shown
    as a layer and read on hover.
    """

    name: str
    rgb: np.ndarray
    sparse: np.ndarray
    depths: dict[str, np.ndarray]
    semantic: np.ndarray | None = None
    gt: np.ndarray | None = None
    outputs: dict[str, np.ndarray] = field(default_factory=dict)
    outputs_of: str = ""
    K: np.ndarray | None = None
    cloud_of: str | None = None
    note: str = ""
    uncertainty: np.ndarray | None = None


def cloud_stride(height: int, width: int, max_points: int = MAX_POINTS) -> int:
    """The smallest pixel step s with at most ``max_points`` pixels on the grid ``[::s, ::s]``."""
    s = max(1, math.ceil(math.sqrt(height * width / max_points)))
    while math.ceil(height / s) * math.ceil(width / s) > max_points:
        s += 1
    return s


def cloud_points(depth: np.ndarray, K: np.ndarray, stride: int, rgb: np.ndarray | None = None) -> PointCloud:
    """The :class:`~semattnet.geometry.PointCloud` of the valid pixels of ``depth`` on the grid ``[::stride]`` x2."""
    from semattnet.geometry import depth_to_points

    grid = np.zeros(depth.shape, dtype=bool)
    grid[::stride, ::stride] = True
    return depth_to_points(np.nan_to_num(depth), K, rgb=rgb, mask=grid)


def _packed(a: np.ndarray) -> str:
    return base64.b64encode(zlib.compress(np.ascontiguousarray(a).tobytes(), 6)).decode("ascii")


def _png(img: np.ndarray) -> str:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img)).save(buf, format="PNG", optimize=True)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _cm(depth: np.ndarray) -> np.ndarray:
    """Depth in metres -> uint16 centimetres (little-endian), 0 = none."""
    d = np.nan_to_num(np.asarray(depth, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    return np.clip(np.round(d * 100.0), 0, 65535).astype("<u2")


class _Builder:
    """Collects one frame's layers (pictures) and values (read on hover)."""

    def __init__(self) -> None:
        self.layers: list[dict[str, str]] = []
        self.values: list[dict[str, object]] = []
        self.arrays: list[dict[str, str]] = []

    def layer(self, key: str, label: str, img: np.ndarray) -> None:
        self.layers.append({"key": key, "label": label, "png": _png(img)})

    def array(self, key: str, a: np.ndarray, dtype: str) -> None:
        self.arrays.append({"key": key, "dtype": dtype, "data": _packed(a)})

    def depth(self, key: str, label: str, depth: np.ndarray, picture: bool = True) -> None:
        from semattnet.viz.depth import colorize_depth

        if picture:
            self.layer(key, label, colorize_depth(depth))
        self.array(key, _cm(depth), "u16")
        self.values.append({"key": key, "label": label, "scale": 0.01, "unit": "m", "digits": 2, "zero_is_empty": True})

    def weight(self, key: str, label: str, conf: np.ndarray) -> None:
        from semattnet.viz.depth import confidence_image

        self.layer(key, label, confidence_image(conf))
        self.array(key, np.clip(np.round(np.nan_to_num(conf) * 255), 0, 255).astype(np.uint8), "u8")
        self.values.append(
            {"key": key, "label": label, "scale": 1 / 255, "unit": "", "digits": 2, "zero_is_empty": False}
        )

    def uncertainty(self, key: str, label: str, unc: np.ndarray) -> None:
        """A per-pixel uncertainty (metres, 0 = none) on "magma" from 0 to its 99th percentile (named in the label)."""
        from semattnet.viz.depth import colorize_depth

        u = np.nan_to_num(np.asarray(unc, dtype=np.float32))
        top = float(np.percentile(u[u > 0], 99)) if np.any(u > 0) else 1.0
        top = max(top, 0.01)
        self.layer(key, f"{label} (0 to {top:.2f} m)", colorize_depth(u, vmax=top, cmap="magma"))
        self.array(key, np.where(u > 0, np.maximum(_cm(u), 1), 0).astype("<u2"), "u16")  # under 1 cm: 1 cm
        self.values.append({"key": key, "label": label, "scale": 0.01, "unit": "m", "digits": 2, "zero_is_empty": True})


def _frame_layers(b: _Builder, f: ViewerFrame, labels: dict[str, str]) -> None:
    """Inputs, ground truth, the intermediates of ``f.outputs_of``, each method's depth and error map."""
    from semattnet.viz.depth import error_map

    b.layer("rgb", "RGB", np.asarray(f.rgb, dtype=np.uint8))
    if f.semantic is not None:
        b.layer("semantic", "Semantics", np.asarray(f.semantic, dtype=np.uint8))
    b.depth("lidar", "LiDAR (sparse input)", f.sparse)
    if f.gt is not None:
        b.depth("gt", "Ground truth", f.gt)
    prefix = labels.get(f.outputs_of, f.outputs_of).split(" (")[0]
    for key, label in _DEPTHS:
        if key in f.outputs:
            b.depth(f"out_{key}", f"{prefix}: {label.lower()}" if prefix else label, f.outputs[key])
    for key, label in _WEIGHTS:
        if key in f.outputs:
            b.weight(f"out_{key}", f"{prefix}: {label.lower()}" if prefix else label, f.outputs[key])
    for method, depth in f.depths.items():
        name = labels.get(method, method).split(" (")[0]
        b.depth(f"depth_{method}", name, depth)
        if f.gt is not None:
            b.layer(f"error_{method}", f"{name}: error map", error_map(depth, f.gt))
    unc = f.uncertainty if f.uncertainty is not None else f.outputs.get("uncertainty")
    if unc is not None:
        of = f.cloud_of or f.outputs_of or list(f.depths)[-1]
        b.uncertainty("uncertainty", f"{labels.get(of, of).split(' (')[0]}: uncertainty", unc)


def _overlay(sparse: np.ndarray) -> str:
    """The LiDAR points as an RGBA picture, transparent where there is no point."""
    from semattnet.viz.depth import colorize_depth

    rgba = np.zeros((*sparse.shape, 4), dtype=np.uint8)
    rgba[..., :3] = colorize_depth(sparse)
    rgba[..., 3] = np.where(sparse > 0, 255, 0)
    return _png(rgba)


def _frame_cloud(b: _Builder, f: ViewerFrame, labels: dict[str, str], max_points: int) -> dict[str, object]:
    """Add the predicted and LiDAR point clouds (cm, int16) to ``b``; the frame's ``cloud`` entries."""
    if f.K is None:
        return {"cloud": None, "cloud_note": "No 3D view: no camera intrinsics (give --K fx,fy,cx,cy or --K kitti)."}
    method = f.cloud_of or list(f.depths)[-1]
    h, w = f.sparse.shape
    stride = cloud_stride(h, w, max_points)
    pred = cloud_points(f.depths[method], f.K, stride, rgb=np.asarray(f.rgb, dtype=np.uint8))
    lidar = cloud_points(f.sparse, f.K, 1)
    keep = slice(None, None, max(1, math.ceil(len(lidar) / max_points)))
    for key, xyz in (("cloud_xyz", pred.xyz), ("lidar_xyz", lidar.xyz[keep])):
        b.array(key, np.clip(np.round(xyz * 100.0), -32768, 32767).astype("<i2"), "i16")
    assert pred.rgb is not None  # cloud_points was given the colours
    b.array("cloud_rgb", pred.rgb, "u8")
    name = labels.get(method, method).split(" (")[0]
    note = (
        f"{name}: {len(pred)} points (a pixel grid of step {stride}), "
        f"LiDAR: {len(lidar.xyz[keep])} points; back-projected with fx {f.K[0, 0]:.1f}, fy {f.K[1, 1]:.1f}, "
        f"cx {f.K[0, 2]:.1f}, cy {f.K[1, 2]:.1f}."
    )
    return {
        "cloud": {
            "label": f"{name} (predicted)",
            "points": len(pred),
            "stride": stride,
            "lidar_points": len(lidar.xyz[keep]),
            "note": note,
        },
        "cloud_note": "",
    }


def _frame_data(f: ViewerFrame, labels: dict[str, str], max_points: int) -> dict[str, object]:
    """Everything the page needs of one frame (JSON-serialisable)."""
    b = _Builder()
    _frame_layers(b, f, labels)
    cloud = _frame_cloud(b, f, labels, max_points)
    keys = [layer["key"] for layer in b.layers]
    default = next((k for k in (f"depth_{f.cloud_of}", f"depth_{list(f.depths)[-1]}") if k in keys), keys[0])
    h, w = f.sparse.shape
    return {
        "name": f.name,
        "note": f.note,
        "width": w,
        "height": h,
        "layers": b.layers,
        "values": b.values,
        "arrays": b.arrays,
        "default_layer": default,
        "lidar_overlay": _overlay(f.sparse),
        **cloud,
    }


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path, suffix=path.suffix) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _write_plotly(out: Path) -> None:
    """Plotly's bundled JavaScript into ``out/plotly.min.js`` (once: kept if already there)."""
    from plotly.offline import get_plotlyjs

    target = out / "plotly.min.js"
    js = get_plotlyjs()
    if not target.is_file() or target.stat().st_size != len(js.encode("utf-8")):
        _write(target, js)


def write_viewer(
    out_dir: str | Path,
    frames: Sequence[ViewerFrame],
    labels: dict[str, str] | None = None,
    title: str = "SemAttNet viewer",
    back: tuple[str, str] | None = None,
    max_points: int = MAX_POINTS,
) -> Path:
    """Write ``viewer.html``, ``plotly.min.js`` and ``viewer/NNN.js`` into ``out_dir``; return the page.

    Args:
        labels: method -> display name.
        back: optional (link text, relative href) shown in the header, e.g. to ``report.html``.
    """
    from html import escape

    if not frames:
        raise InputError("the viewer needs at least one frame")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _write_plotly(out)
    listing = []
    for i, f in enumerate(frames):
        src = f"viewer/{i:03d}.js"
        data = json.dumps(_frame_data(f, labels or {}, max_points), separators=(",", ":"))
        _write(out / src, f"semattnetViewer.add({i},{data});\n")
        listing.append({"name": f.name, "src": src})
    page = Template((resources.files("semattnet.viz") / "_viewer.html").read_text(encoding="utf-8"))
    script = (resources.files("semattnet.viz") / "_viewer.js").read_text(encoding="utf-8")
    link = f'<a href="{escape(back[1])}">{escape(back[0])}</a>' if back else ""
    meta = json.dumps({"frames": listing}).replace("</", "<\\/")
    html = page.substitute(title=escape(title), back=link, meta=meta, script=script)
    _write(out / "viewer.html", html)
    return out / "viewer.html"


def write_prediction_report(
    out_dir: str | Path,
    frames: Sequence[FramePaths],
    K: np.ndarray | None = None,
    log: Callable[[str], None] = print,
) -> Path:
    """The viewer for what :func:`semattnet.inference.complete_folder` wrote into ``out_dir``.

    ``frames``: the :class:`~semattnet.data.pairing.FramePaths` that were completed; each
    prediction is read back from ``NAME.npy`` if written, else from ``NAME.png``, and its uncertainty
    (``predict --uncertainty``) from ``uncertainty/NAME.npy`` or ``uncertainty/NAME.png`` when there.
    No ground truth; the 3D view needs ``K`` (the frames' intrinsics).
    """
    from semattnet.data.io import read_depth, read_image

    def read(stem: Path) -> np.ndarray | None:
        npy, png = stem.with_name(stem.name + ".npy"), stem.with_name(stem.name + ".png")
        return np.load(npy) if npy.is_file() else read_depth(png) if png.is_file() else None

    out = Path(out_dir)
    shown = []
    for fr in frames:
        depth = read(out / fr.name)
        if depth is None:
            depth = read_depth(out / f"{fr.name}.png")  # missing: read_depth's one-line error
        sem = read_image(fr.semantic) if fr.semantic is not None else None
        shown.append(
            ViewerFrame(
                fr.name,
                read_image(fr.rgb),
                read_depth(fr.sparse),
                {"prediction": depth},
                semantic=sem,
                K=K,
                uncertainty=read(out / "uncertainty" / fr.name),
            )
        )
    page = write_viewer(out, shown, {"prediction": "Completed depth"}, title="semattnet predict: viewer")
    log(f"viewer: {page.resolve()}")
    return page
