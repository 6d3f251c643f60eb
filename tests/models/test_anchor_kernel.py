"""The C++ classical completion and distance transform (models.anchor_kernel) against the PyTorch path: the same
completion (the Gaussian's sums in the same order), the same fill steps, the same distances; the PyTorch path when
the kernel cannot be used."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from semattnet import InputError
from semattnet.models import anchor, anchor_kernel
from semattnet.models.anchor import classical_fill_step, complete_classical
from semattnet.models.uncertainty import lidar_distance

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "kitti_sample"
needs_kernel = pytest.mark.skipif(
    not anchor_kernel.available(), reason="no C++ toolchain for the classical-completion kernel"
)


def _sparse(b: int, h: int, w: int, share: float, seed: int, top: float = 100.0) -> torch.Tensor:
    """(b, 1, h, w) depth in (0, top] at about ``share`` of the pixels."""
    g = torch.Generator().manual_seed(seed)
    depth = top * (1 - torch.rand(b, 1, h, w, generator=g))
    return depth * (torch.rand(b, 1, h, w, generator=g) < share)


def _same(sparse: torch.Tensor, max_depth: float = 100.0) -> None:
    """Completion, fill step and distance: the kernel's equal to the PyTorch path's."""
    want, want_step = anchor._complete(sparse, max_depth, impl="pytorch")
    got, got_step = anchor._complete(sparse, max_depth)
    torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-6)
    assert got_step is not None and torch.equal(got_step, want_step), int((got_step != want_step).sum())
    assert torch.equal(complete_classical(sparse, max_depth), got)  # without the fill step: the same completion
    assert torch.equal(lidar_distance(sparse), lidar_distance(sparse, impl="pytorch"))


@needs_kernel
@pytest.mark.parametrize("share", [0.0, 0.003, 0.05, 0.3, 1.0])
@pytest.mark.parametrize("shape", [(1, 1, 1), (1, 3, 7), (2, 1, 40), (2, 40, 1), (1, 2, 2), (3, 37, 91), (1, 64, 200)])
def test_the_kernel_equals_the_pytorch_path(shape: tuple[int, int, int], share: float) -> None:
    _same(_sparse(*shape, share=share, seed=sum(shape) + int(share * 1000)))


@needs_kernel
@pytest.mark.parametrize("share", [0.01, 0.05, 1.0])
def test_the_kernel_equals_the_pytorch_path_at_full_size(share: float) -> None:
    _same(_sparse(1, 375, 1242, share=share, seed=7))


@needs_kernel
def test_a_batch_mixing_an_empty_a_full_and_a_sparse_image() -> None:
    """Each image as alone (they run in parallel): the empty one stays 0, every step 5, distance H + W."""
    sparse = torch.cat([torch.zeros(1, 1, 30, 50), _sparse(1, 30, 50, 1.0, 1), _sparse(1, 30, 50, 0.02, 2)])
    _same(sparse)
    out, step = complete_classical(sparse), classical_fill_step(sparse)
    assert not out[0].any() and bool((step[0] == len(anchor.FILL_STEPS) - 1).all())
    assert bool((lidar_distance(sparse)[0] == 80).all())
    for i in range(3):
        assert torch.equal(out[i : i + 1], complete_classical(sparse[i : i + 1].clone()))


@needs_kernel
def test_values_at_and_above_max_depth_and_an_unrounded_max_depth() -> None:
    """Depths are clamped to max_depth, inverted as max_depth + 1 - d (float32 sums, as PyTorch's)."""
    sparse = _sparse(2, 41, 67, 0.05, 3, top=120.0)
    sparse[0, 0, 5, ::3] = 100.0
    sparse[1, 0, ::4, 9] = 80.3
    for max_depth in (100.0, 80.3, 15.0):
        _same(sparse, max_depth)


@needs_kernel
@pytest.mark.parametrize("seed", range(6))
def test_lines_blocks_and_holes(seed: int) -> None:
    """Measurements in a few scan lines with wide gaps (the large-hole fills and both extensions do the work)."""
    g = torch.Generator().manual_seed(seed)
    h, w = 48 + seed, 97
    sparse = torch.zeros(1, 1, h, w)
    for row in torch.randint(h // 3, h, (4,), generator=g).tolist():
        sparse[0, 0, row, :] = 5 + 60 * torch.rand(w, generator=g) * (torch.rand(w, generator=g) < 0.4)
    sparse[..., :, 40 + seed : 70] = 0  # a hole wider than the largest fill
    _same(sparse)


@needs_kernel
@pytest.mark.skipif(not (SAMPLE / "kitti_raw").is_dir(), reason="no bundled KITTI sample")
def test_the_real_kitti_frame() -> None:
    from semattnet.evaluation.zero_shot import real_frames

    for frame in real_frames(SAMPLE):
        sparse = torch.as_tensor(frame.sparse).float()[None, None]
        _same(sparse)
        _same(sparse[..., -352:, 13:1229].contiguous())


@needs_kernel
def test_the_kernel_runs_only_where_it_may(monkeypatch: pytest.MonkeyPatch) -> None:
    """float32 CPU tensors outside autograd, impl "auto"; the others take the PyTorch path."""
    calls: list[str] = []
    real = anchor_kernel.complete
    monkeypatch.setattr(anchor_kernel, "complete", lambda *a, **k: calls.append("complete") or real(*a, **k))
    sparse = _sparse(1, 20, 30, 0.1, 4)
    complete_classical(sparse)
    assert calls == ["complete"]
    complete_classical(sparse, impl="pytorch")
    complete_classical(sparse.double())
    complete_classical(sparse.clone().requires_grad_())
    assert calls == ["complete"]
    assert anchor_kernel.usable(sparse) and not anchor_kernel.usable(sparse, "pytorch")


def test_without_the_kernel_the_pytorch_path_is_used(monkeypatch: pytest.MonkeyPatch) -> None:
    """Unavailable (no compiler, a failed build, SEMATTNET_NO_CPP): the same results, the kernel never called."""
    monkeypatch.setattr(anchor_kernel.KERNEL, "module", None)
    monkeypatch.setattr(anchor_kernel.KERNEL, "failed", "no C++ compiler (c++ not found; install one or set CXX)")

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the kernel was called")

    monkeypatch.setattr(anchor_kernel, "complete", refuse)
    monkeypatch.setattr(anchor_kernel, "distance", refuse)
    sparse = _sparse(2, 25, 33, 0.05, 5)
    want, want_step = anchor._complete_torch(sparse, 100.0)
    assert torch.equal(complete_classical(sparse), want) and torch.equal(classical_fill_step(sparse), want_step)
    assert torch.equal(lidar_distance(sparse), lidar_distance(sparse, impl="pytorch"))
    with pytest.raises(RuntimeError, match="no C\\+\\+ compiler"):
        anchor_kernel.KERNEL.require()


def test_the_switch_disables_the_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(anchor_kernel.KERNEL, "module", None)
    monkeypatch.setattr(anchor_kernel.KERNEL, "failed", None)
    monkeypatch.setenv("SEMATTNET_NO_CPP", "1")
    assert not anchor_kernel.available() and anchor_kernel.KERNEL.failed == "disabled by SEMATTNET_NO_CPP"


def test_inputs_are_checked_before_either_path() -> None:
    bad = torch.zeros(1, 1, 4, 4)
    bad[0, 0, 1, 1] = float("nan")
    for impl in ("auto", "pytorch"):
        with pytest.raises(InputError, match="NaN"):
            complete_classical(bad, impl=impl)  # type: ignore[arg-type]
        with pytest.raises(InputError, match=r"\(B, 1, H, W\)"):
            classical_fill_step(torch.zeros(1, 2, 4, 4), impl=impl)  # type: ignore[arg-type]
        with pytest.raises(InputError, match="negative"):
            complete_classical(-torch.ones(1, 1, 3, 3), impl=impl)  # type: ignore[arg-type]
