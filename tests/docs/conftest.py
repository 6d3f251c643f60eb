"""Shared, session-wide inputs for the documentation tests: one tiny data tree, one tiny model, one built site."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.docs._blocks import REPO, shim_bin

#: What the pages' examples find in their working folder (the pages say which names they use).
WORKSPACE_NOTE = (
    "data/kitti (tiny synthetic tree), model.safetensors (width 0.125), frames/, RAW_ROOT/, VOID_ROOT/, "
    "NYU_ROOT/ (one labelled test frame)"
)


def _tiny_model(path: Path) -> None:
    import torch

    import semattnet
    from semattnet.weights import save_safetensors

    torch.manual_seed(0)
    save_safetensors(semattnet.build_model("semattnet", width=0.125).state_dict(), path)


def _frames(tree: Path, out: Path) -> None:
    """frames/{rgb,sparse,semantic}/f000N.png: the tiny tree's val_select frames; the first also as frame.png,
    lidar.png and semantic.png; frames/gt/ the ground truth."""
    sel = tree / "data_depth_selection" / "val_selection_cropped"
    kinds = (("image", "rgb"), ("velodyne_raw", "sparse"), ("semantic", "semantic"), ("groundtruth_depth", "gt"))
    for src, dst in kinds:
        (out / "frames" / dst).mkdir(parents=True)
        for i, f in enumerate(sorted((sel / src).glob("*.png"))):
            shutil.copy(f, out / "frames" / dst / f"f{i:04d}.png")
    for src, dst in (("rgb", "frame.png"), ("sparse", "lidar.png"), ("semantic", "semantic.png")):
        shutil.copy(out / "frames" / src / "f0000.png", out / dst)


@pytest.fixture(scope="session")
def docs_workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The folder every page's examples start from (copied per page)."""
    from tests.docs._blocks import run_semattnet

    root = tmp_path_factory.mktemp("docs-workspace")
    old = Path.cwd()
    os.chdir(root)
    try:
        run_semattnet(
            ["synth", "--out", "data/kitti", "--frames", "4", "--eval-frames", "2", "--size", "64x96"], "setup"
        )
    finally:
        os.chdir(old)
    _tiny_model(root / "model.safetensors")
    _frames(root / "data" / "kitti", root)
    shutil.copytree(REPO / "tests" / "data" / "kitti_sample" / "kitti_raw", root / "RAW_ROOT")
    (root / "benchmarks").symlink_to(REPO / "benchmarks")  # the pages run `python benchmarks/...` as a user would
    from tests.data._datasets import make_void

    make_void(root / "VOID_ROOT", train=2, test=2, h=64, w=96)  # VOID's folders and list files, tiny
    from tests.data._datasets import make_nyu

    make_nyu(root / "NYU_ROOT", train=0, test=1, label=True)  # one sparse-to-dense HDF5 frame, NYU-40 labels
    return root


@pytest.fixture
def page_env(tmp_path: Path) -> dict[str, str]:
    """Offline, a private cache, this checkout's package on PATH and PYTHONPATH, one thread."""
    src = str(REPO / "src")
    return {
        "SEMATTNET_OFFLINE": "1",
        "HF_HUB_OFFLINE": "1",
        "SEMATTNET_CACHE": str(tmp_path / "cache"),
        "MPLBACKEND": "Agg",
        "OMP_NUM_THREADS": "1",
        "PYTHONPATH": os.pathsep.join([src, *filter(None, [os.environ.get("PYTHONPATH")])]),
        "PATH": os.pathsep.join(
            [str(shim_bin(tmp_path / "bin")), str(Path(sys.executable).parent), os.environ.get("PATH", "")]
        ),
    }


@pytest.fixture(scope="session")
def built_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``mkdocs build --strict`` of this checkout into a temporary folder (what ``make docs`` runs)."""
    pytest.importorskip("mkdocs", reason="the docs extra is not installed (pip install -e '.[docs]')")
    site = tmp_path_factory.mktemp("site")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(REPO / "src")},
    )
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout[-4000:]}{proc.stderr[-4000:]}"
    return site


def pytest_terminal_summary(terminalreporter) -> None:  # type: ignore[no-untyped-def]
    """The share of documentation blocks that ran (issue 24 asks for the count in the output)."""
    from tests.docs.test_code_blocks import coverage_line

    terminalreporter.write_line(f"docs code blocks: {coverage_line()}")
