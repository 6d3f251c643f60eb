"""Training the generalist (:mod:`semattnet.training.generalist`): the bank, an exact resume, the per-cell
calibration of its uncertainty and the packed weights it ships as."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from semattnet.models.generalist import Generalist
from semattnet.training.generalist import (
    GeneralistTrainConfig,
    finish_generalist,
    train_generalist,
    write_bank,
)


@pytest.fixture(scope="module")
def bank(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_bank(tmp_path_factory.mktemp("bank"), 3, log=lambda m: None)


def _config(bank: Path, out: Path) -> GeneralistTrainConfig:
    return GeneralistTrainConfig(
        model="semattnet_rt_generalist",
        bank=str(bank),
        out=str(out),
        steps=4,
        batch=2,
        crop=(64, 96),
        width=0.25,
        save_every=2,
    )


class _Killed(Exception):
    pass


def test_a_killed_run_resumes_into_the_uninterrupted_weights(bank: Path, tmp_path: Path) -> None:
    whole = train_generalist(_config(bank, tmp_path / "whole"), log=lambda m: None)

    def kill_at_step_2(line: str) -> None:
        if line.startswith("step 2/"):
            raise _Killed

    with pytest.raises(_Killed):
        train_generalist(_config(bank, tmp_path / "killed"), log=kill_at_step_2)
    lines: list[str] = []
    resumed = train_generalist(_config(bank, tmp_path / "killed"), resume=True, log=lines.append)
    assert lines[0] == "resumed at step 2"
    for (name, a), b in zip(whole.state_dict().items(), resumed.state_dict().values(), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0, msg=name)


def test_calibration_and_the_packed_weights_carry_the_three_terms(bank: Path, tmp_path: Path) -> None:
    from semattnet.weights import from_pretrained

    cfg = _config(bank, tmp_path)
    model = train_generalist(cfg, log=lambda m: None)
    lines: list[str] = []
    packed = finish_generalist(model, cfg, frames=6, log=lines.append, size=(96, 160))
    k, f, g = model.calibration.tolist()
    assert k > 0 and f >= 0 and g >= 0
    assert lines == [
        f"uncertainty calibrated on 1 held-out world frames in each of 6 cells: sigma = {k:.3f} u + {f:.4f} depth + "
        f"{g:.2f} depth * distance / height"
    ]
    loaded = from_pretrained(str(packed), map_location="cpu")
    assert isinstance(loaded, Generalist)
    np.testing.assert_allclose(loaded.calibration.numpy(), model.calibration.numpy(), rtol=1e-3)  # float16
