from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

from tests._helpers import REPO, random_inputs  # noqa: F401  (re-exported for old imports)


@pytest.fixture(autouse=True)
def _default_sigchld() -> Iterator[None]:
    """SIGCHLD back to its default after each test. A DataLoader with workers installs torch's SIGCHLD handler
    for the rest of the process; with it, three full runs here died in ``os.waitpid`` of a later test that
    waits for its child (a kernel-forced SIGSEGV, si_code SI_KERNEL, while delivering that child's SIGCHLD to
    the handler). A child's exit then reaches no handler in tests that do not run a DataLoader."""
    yield
    if signal.getsignal(signal.SIGCHLD) not in (signal.SIG_DFL, signal.SIG_IGN, None):
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)


@pytest.fixture(autouse=True)
def _deterministic() -> None:
    torch.manual_seed(0)


@pytest.fixture(scope="session")
def tiny_weights(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A random three-branch SemAttNet at width 0.125 (seed 0) as safetensors: for tests of a code path that
    needs weights, not their accuracy."""
    from tests.inference._raw_sample import tiny_checkpoint

    return tiny_checkpoint(tmp_path_factory.mktemp("tiny-weights") / "tiny.safetensors")


def _devices() -> list[str]:
    return ["cpu", "cuda"] if torch.cuda.is_available() else ["cpu"]


@pytest.fixture(params=_devices())
def device(request: pytest.FixtureRequest) -> torch.device:
    """Every available device (CPU always; CUDA where present)."""
    return torch.device(request.param)


@pytest.fixture(params=[torch.float32, torch.float64], ids=["float32", "float64"])
def dtype(request: pytest.FixtureRequest) -> torch.dtype:
    """The floating-point types the numerics are tested in on every device."""
    return request.param


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Downloads and exported engines go to a temporary cache, never the user's ($SEMATTNET_CACHE)."""
    old = os.environ.get("SEMATTNET_CACHE")
    os.environ["SEMATTNET_CACHE"] = str(tmp_path_factory.mktemp("semattnet-cache"))
    yield
    if old is None:
        os.environ.pop("SEMATTNET_CACHE", None)
    else:
        os.environ["SEMATTNET_CACHE"] = old


@pytest.fixture(autouse=True, scope="session")
def _one_thread_per_worker() -> None:
    """Under xdist each worker computes on one thread: two workers on a 2-core machine, not four threads."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        torch.set_num_threads(1)
