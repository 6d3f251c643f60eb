"""`semattnet segment`: TorchScript / ONNX / torchvision segmenters, mirrored layout, resume."""

from __future__ import annotations

import shutil
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from torch import nn

from semattnet import DataError, InputError
from semattnet.cli import main
from semattnet.data.io import read_image, write_image
from semattnet.palette import IGNORE_ID, UNKNOWN_COLOR, colors_to_ids
from semattnet.segmentation.segmenter import Segmenter, load_segmenter, segment_folder


class TinySegNet(nn.Module):
    """Random 19-class segmenter that predicts at half resolution (like real networks)."""

    def __init__(self, classes: int = 19) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.body = nn.Sequential(nn.Conv2d(3, 8, 3, stride=2, padding=1), nn.ReLU(), nn.Conv2d(8, classes, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x)


def _tree(root: Path, sizes: list[tuple[int, int]]) -> list[Path]:
    """Images in a KITTI raw-like tree: <date>/<drive>/image_02/data/<frame>.png."""
    rng = np.random.default_rng(0)
    paths = []
    for i, (h, w) in enumerate(sizes):
        drive = f"2011_09_26_drive_{i // 3:04d}_sync"
        p = root / "2011_09_26" / drive / "image_02" / "data" / f"{i:010d}.png"
        write_image(p, rng.integers(0, 256, (h, w, 3), dtype=np.uint8))
        paths.append(p)
    return paths


def _check_maps(images: Path, out: Path, sources: list[Path]) -> None:
    for src in sources:
        target = out / src.relative_to(images)
        assert target.is_file(), target
        sem = read_image(target)
        assert sem.shape == read_image(src).shape  # the input size
        ids = colors_to_ids(sem, allow_unknown=False, source=str(target))  # only palette colours
        assert len(np.unique(ids)) > 1  # a random net still predicts several classes


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("models")
    net = TinySegNet().eval()
    ts = d / "seg.pt"
    torch.jit.script(net).save(str(ts))
    onnx_path = d / "seg.onnx"
    x = torch.rand(1, 3, 32, 48)
    dims = {"x": {0: "batch", 2: "height", 3: "width"}}
    torch.onnx.export(
        net, (x,), str(onnx_path), input_names=["x"], output_names=["logits"], dynamic_axes=dims, dynamo=False
    )
    return {"torchscript": ts, "onnx": onnx_path}


@pytest.mark.parametrize("kind", ["torchscript", "onnx"])
def test_segment_cli_end_to_end(kind: str, exported: dict[str, Path], tmp_path: Path) -> None:
    images, out = tmp_path / "kitti_raw", tmp_path / "semantic"
    sources = _tree(images, [(40, 64)] * 5 + [(36, 50)] * 2)  # two sizes: batches never mix them
    res = CliRunner().invoke(
        main,
        [
            "segment",
            "--model",
            str(exported[kind]),
            "--images",
            str(images),
            "--out",
            str(out),
            "--batch-size",
            "3",
            "--device",
            "cpu",
        ],
    )
    assert res.exit_code == 0, res.output
    assert "wrote 7 maps" in res.output and "0 already there" in res.output
    _check_maps(images, out, sources)


def test_torchscript_and_onnx_agree(exported: dict[str, Path], tmp_path: Path) -> None:
    imgs = np.random.default_rng(1).integers(0, 256, (2, 40, 64, 3), dtype=np.uint8)
    a = load_segmenter(str(exported["torchscript"]), "cpu")(imgs)
    b = load_segmenter(str(exported["onnx"]), "cpu")(imgs)
    assert a.shape == (2, 40, 64) and a.dtype == np.uint8
    assert (a == b).mean() > 0.999  # same network; arg-max ties may differ by float rounding


def test_interrupted_run_resumes_without_redoing(exported: dict[str, Path], tmp_path: Path) -> None:
    images, out = tmp_path / "img", tmp_path / "sem"
    sources = _tree(images, [(32, 48)] * 6)
    real = load_segmenter(str(exported["torchscript"]), "cpu")
    calls = {"n": 0}

    def crashing(x: torch.Tensor) -> torch.Tensor:
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt  # the user presses Ctrl-C during the third batch
        return real.network(x)  # type: ignore[misc]

    with pytest.raises(KeyboardInterrupt):
        segment_folder(Segmenter(crashing, "crashing", "cpu"), images, out, batch_size=2, progress=False)
    done = sorted(out.rglob("*.png"))
    assert len(done) == 4 and not list(out.rglob(".*"))  # two whole batches, no partial file
    stamps = {p: p.stat().st_mtime_ns for p in done}
    seen: list[int] = []

    def counting(x: torch.Tensor) -> torch.Tensor:
        seen.append(x.shape[0])
        return real.network(x)  # type: ignore[misc]

    summary = segment_folder(Segmenter(counting, "counting", "cpu"), images, out, batch_size=2, progress=False)
    assert (summary.written, summary.skipped, summary.total) == (2, 4, 6)
    assert seen == [2]  # only the two missing images went through the network
    assert all(p.stat().st_mtime_ns == t for p, t in stamps.items())
    _check_maps(images, out, sources)
    again = segment_folder(Segmenter(counting, "counting", "cpu"), images, out, progress=False)
    assert again.written == 0 and seen == [2]


def test_kitti_loader_reads_segmented_maps(tmp_path: Path) -> None:
    from semattnet.data.kitti.splits import KittiDepthCompletion
    from semattnet.synthetic.tree import write_synthetic_kitti

    root = tmp_path / "kitti"
    write_synthetic_kitti(root, frames=3, size=(64, 96), eval_frames=2, workers=1)
    shutil.rmtree(root / "semantic")
    res = CliRunner().invoke(
        main, ["segment", "--model", "unknown", "--images", str(root / "kitti_raw"), "--out", str(root / "semantic")]
    )
    assert res.exit_code == 0, res.output
    sample = KittiDepthCompletion(root, "train")[0]
    assert (sample["semantic"] == torch.tensor(UNKNOWN_COLOR, dtype=torch.float32).view(3, 1, 1)).all()


def test_label_id_networks_and_id_outputs() -> None:
    imgs = np.zeros((1, 8, 8, 3), dtype=np.uint8)

    def label_logits(x: torch.Tensor) -> torch.Tensor:
        out = torch.zeros(x.shape[0], 34, 4, 4)
        out[:, 26] = 1.0  # labelId 26 = car
        return out

    assert (Segmenter(label_logits, "labels")(imgs) == 13).all()  # trainId of car
    assert (Segmenter(lambda x: {"out": torch.zeros(1, 19, 8, 8)}, "dict")(imgs) == 0).all()
    assert (Segmenter(lambda x: torch.full((1, 2, 2), 10), "ids")(imgs) == 10).all()
    assert (Segmenter(None, "unknown")(imgs) == IGNORE_ID).all()
    with pytest.raises(ValueError, match="bad: returned 7 classes"):
        Segmenter(lambda x: torch.zeros(1, 7, 8, 8), "bad")(imgs)


def test_bad_specs_give_one_line_errors(tmp_path: Path) -> None:
    images = tmp_path / "img"
    _tree(images, [(16, 16)])
    for spec, message in (
        (str(tmp_path / "missing.onnx"), "no such model file"),
        ("torchvision:deeplabv3_resnet50", "expected torchvision:ARCH:WEIGHTS"),
    ):
        args = ["segment", "--model", spec, "--images", str(images), "--out", str(tmp_path / "o")]
        res = CliRunner().invoke(main, args)
        assert res.exit_code != 0 and message in res.output and "Traceback" not in res.output
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="junk.onnx: not a loadable ONNX model"):
        load_segmenter(str(junk), "cpu")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no .png/.jpg/.jpeg images"):
        segment_folder(Segmenter(None, "unknown"), empty, tmp_path / "x")


def test_torchvision_spec(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The torchvision path with a stand-in module (torchvision is not installed here)."""

    class FakeDeepLab(nn.Module):
        def __init__(self, num_classes: int, aux_loss: bool) -> None:
            super().__init__()
            self.backbone = nn.Conv2d(3, 4, 1)
            self.classifier = nn.Sequential(
                nn.Identity(), nn.Identity(), nn.Identity(), nn.Identity(), nn.Conv2d(4, num_classes, 1)
            )

        def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
            return {"out": self.classifier(self.backbone(x))}

    built: dict[str, object] = {}

    def deeplabv3_resnet50(weights=None, weights_backbone=None, num_classes=21, aux_loss=None):  # type: ignore[no-untyped-def]
        built.update(weights=weights, weights_backbone=weights_backbone, num_classes=num_classes, aux=aux_loss)
        return FakeDeepLab(num_classes, bool(aux_loss))

    seg = types.ModuleType("torchvision.models.segmentation")
    seg.deeplabv3_resnet50 = deeplabv3_resnet50  # type: ignore[attr-defined]
    models = types.ModuleType("torchvision.models")
    models.segmentation = seg  # type: ignore[attr-defined]
    tv = types.ModuleType("torchvision")
    tv.models = models  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "torchvision", tv)
    monkeypatch.setitem(sys.modules, "torchvision.models", models)
    monkeypatch.setitem(sys.modules, "torchvision.models.segmentation", seg)

    trained = FakeDeepLab(19, False)
    with torch.no_grad():
        trained.classifier[4].bias.copy_(torch.arange(19.0))  # always predicts the last class
    weights = tmp_path / "w.pth"
    torch.save({"model": trained.state_dict()}, weights)
    s = load_segmenter(f"torchvision:deeplabv3_resnet50:{weights}", "cpu")
    assert built == {"weights": None, "weights_backbone": None, "num_classes": 19, "aux": False}  # no download
    assert (s(np.zeros((1, 8, 8, 3), dtype=np.uint8)) == 18).all()
    with pytest.raises(InputError, match="no architecture 'nope'"):
        load_segmenter(f"torchvision:nope:{weights}", "cpu")
    partial = tmp_path / "partial.pth"
    torch.save({k: v for k, v in trained.state_dict().items() if not k.startswith("backbone.")}, partial)
    with pytest.raises(DataError, match=r"partial.pth: does not fit torchvision's deeplabv3_resnet50: .*Missing key"):
        load_segmenter(f"torchvision:deeplabv3_resnet50:{partial}", "cpu")
    # a pickle that would run code: torch.load(weights_only=True) refuses it, and the bare
    # pickle.UnpicklingError it raises becomes a DataError (one line in the CLI), the code never runs
    marker = tmp_path / "ran"
    evil = tmp_path / "evil.pth"
    torch.save({"model": _OpensAFile(marker)}, evil)
    with pytest.raises(DataError, match=r"evil.pth: not a loadable \(weights-only\) PyTorch state dict"):
        load_segmenter(f"torchvision:deeplabv3_resnet50:{evil}", "cpu")
    assert not marker.exists()


class _OpensAFile:
    """Unpickling this would call ``open(path, "w")``: a stand-in for code a pickle could run."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self) -> tuple[object, tuple[str, str]]:
        return open, (str(self.path), "w")
