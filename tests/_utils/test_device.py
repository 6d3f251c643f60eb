"""Device and number-format rules (the one home of the --amp table)."""

from __future__ import annotations

import pytest
import torch

from semattnet._utils.device import amp_dtype, autocast, now, resolve_device


def test_amp_table_and_errors() -> None:
    assert amp_dtype("bf16") is torch.bfloat16 and amp_dtype("fp16") is torch.float16 and amp_dtype("none") is None
    with pytest.raises(ValueError, match="amp must be one of"):
        amp_dtype("int8")


def test_autocast_none_is_float32() -> None:
    with autocast(torch.device("cpu"), "none"):
        assert (torch.ones(2, 2) @ torch.ones(2, 2)).dtype == torch.float32
    with autocast(torch.device("cpu"), "bf16"):
        assert (torch.ones(2, 2) @ torch.ones(2, 2)).dtype == torch.bfloat16


def test_resolve_device_and_clock() -> None:
    assert resolve_device("cpu") == torch.device("cpu")
    if not torch.cuda.is_available():
        assert resolve_device("auto") == torch.device("cpu")
        with pytest.raises(ValueError, match="CUDA is not available"):
            resolve_device("cuda")
    a = now(torch.device("cpu"))
    assert now(torch.device("cpu")) >= a
