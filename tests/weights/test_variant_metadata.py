"""A weights file whose metadata names another variant than its tensors were trained as (another encoder, a
generalist, another width), as safetensors or packed: refused in one line naming the file and what its metadata
names, never loaded as that variant."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import semattnet
from semattnet.models.config import SemAttNetConfig
from semattnet.weights.builder import WeightsMismatchError
from semattnet.weights.checkpoint import Checkpoint, save_safetensors
from semattnet.weights.packed import encode_packed


@pytest.fixture(scope="module")
def rt_s() -> torch.nn.Module:
    torch.manual_seed(0)
    return semattnet.build_model("semattnet_rt_s", width=0.125)


def _named(name: str) -> SemAttNetConfig:
    """The config of variant ``name`` at width 0.125 (``width``: rt_s at width 0.25)."""
    if name == "width":
        return semattnet.build_model("semattnet_rt_s", width=0.25).config
    with torch.device("meta"):  # the config only: no full-width parameters to initialise
        config: SemAttNetConfig = semattnet.build_model(name).config
    return config.replace(width=0.125)


@pytest.mark.parametrize("packed", [False, True], ids=["safetensors", "packed"])
@pytest.mark.parametrize(
    ("named", "said"),
    [("semattnet_rt_m", "encoder 'lite_s2'"), ("semattnet_rt_generalist", "anchor 'classical'"), ("width", "0.25")],
)
def test_weights_whose_metadata_names_another_variant_are_refused_naming_the_file(
    rt_s: torch.nn.Module, tmp_path: Path, named: str, said: str, packed: bool
) -> None:
    config = _named(named)
    path = tmp_path / ("w.smpk" if packed else "w.safetensors")
    if packed:
        path.write_bytes(encode_packed(rt_s.state_dict(), config.to_dict(), {}))
    else:
        save_safetensors(Checkpoint(path, rt_s.state_dict(), "torch", config=config), path)
    with pytest.raises(WeightsMismatchError) as info:
        semattnet.from_pretrained(path)
    message = str(info.value)
    assert message.startswith(f"{path}: the config in the file's metadata (") and "\n" not in message, message
    assert said in message and "contradicts itself" in message, message
