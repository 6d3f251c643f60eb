"""The encoder interface: every registered encoder, and the authors' ResNet encoder against the paper's branches."""

from __future__ import annotations

import pytest
import torch

import semattnet
from semattnet._errors import InputError
from semattnet.models.encoders import (
    Encoder,
    FeatureInfo,
    ResNetEncoder,
    UnknownEncoderError,
    create_encoder,
    encoder_spec,
    list_encoders,
)
from semattnet.weights.checkpoint_filter import authors_encoder_filter

#: A tiny width per registered encoder (stem first); a new encoder needs its row here.
FIXTURES: dict[str, tuple[int, ...]] = {
    "resnet": (4, 8, 8, 16),
    "lite_s4": (4, 8, 8, 16),
    "lite_s2": (4, 8, 8, 8, 16),
    "lite_s4_wide": (4, 8, 8, 16),
    "lite_s2_deep": (4, 8, 8, 8, 16),
}


def _sizes(name: str) -> tuple[int, ...]:
    if name not in FIXTURES:
        pytest.fail(f"encoder {name!r} has no fixture: add its tiny widths to FIXTURES in {__file__}")
    return FIXTURES[name]


def test_registry_has_the_authors_encoder_first_and_a_fixture_per_encoder() -> None:
    assert list_encoders()[0] == "resnet"
    assert set(FIXTURES) == set(list_encoders())


@pytest.mark.parametrize("name", list_encoders())
def test_encoder_features_match_feature_info(name: str) -> None:
    enc = create_encoder(name, 3, _sizes(name))
    assert isinstance(enc, Encoder) and isinstance(enc, torch.nn.Module)
    info = enc.feature_info
    for b, h, w in ((1, 32, 64), (2, 64, 32)):
        stem, feats = enc(torch.rand(b, 3, h, w))
        assert stem.shape == (b, info.stem_channels, h // info.stem_stride, w // info.stem_stride)
        assert [f.shape for f in feats] == [
            (b, c, h // s, w // s) for s, c in zip(info.strides, info.channels, strict=True)
        ]


@pytest.mark.parametrize("name", list_encoders())
def test_encoder_hook_widens_the_next_stage_and_gradients_flow(name: str) -> None:
    sizes = _sizes(name)
    enc = create_encoder(name, 3, sizes, extra=[2] * (len(sizes) - 1))
    seen = []

    def hook(i: int, x: torch.Tensor) -> torch.Tensor:
        seen.append(i)
        return torch.cat((x, x[:, :2]), dim=1)

    x = torch.rand(2, 3, 64, 64, requires_grad=True)
    _, feats = enc(x, hook)
    feats[-1].sum().backward()
    assert seen == list(range(len(sizes) - 2)) and x.grad is not None and x.grad.abs().sum() > 0
    assert all(p.grad is not None for p in enc.parameters())


def test_bad_encoder_requests_are_one_line_errors() -> None:
    with pytest.raises(UnknownEncoderError, match="unknown encoder 'mobilenet'; available: resnet"):
        create_encoder("mobilenet", 3)
    with pytest.raises(InputError, match="channels must be 2"):
        create_encoder("resnet", 3, (8,))
    with pytest.raises(InputError, match="2 extra widths for 3 stages"):
        create_encoder("resnet", 3, (4, 8, 8, 16), extra=(1, 2))
    with pytest.raises(InputError, match="no features at stride 8"):
        FeatureInfo(4, 1, (2, 4), (8, 8)).channels_at(8)
    assert encoder_spec("resnet").channels[0] == 32


@pytest.mark.parametrize(("branch", "in_chans"), [("rgb", 4), ("segment", 5), ("depth", 3)])
def test_authors_keys_load_into_the_resnet_encoder(branch: str, in_chans: int) -> None:
    """The checkpoint filter maps every authors' encoder key (full model: ``backbone.``) onto ResNetEncoder."""
    model = semattnet.build_model("semattnet", width=0.125)
    w = model.config.widths
    widths = {"rgb": w.base, "segment": w.sg, "depth": w.dg}[branch]
    fused = {"rgb": widths, "segment": w.fused_sg, "depth": w.fused_dg}[branch]
    scales = (2, 4, 8, 16, 32)
    enc = ResNetEncoder(
        in_chans, [w.base[1], *(widths[s] for s in scales)], [fused.get(s, widths[s]) - widths[s] for s in scales]
    )
    enc.load_state_dict(authors_encoder_filter(model.state_dict(), branch), strict=True)


def test_resnet_encoder_reproduces_the_colour_branch() -> None:
    torch.manual_seed(0)
    backbone = semattnet.build_model("semattnet_backbone", width=0.125).eval()
    c = backbone.config.widths.base
    enc = ResNetEncoder(4, [c[s] for s in (1, 2, 4, 8, 16, 32)]).eval()
    enc.load_state_dict(authors_encoder_filter(backbone.state_dict(), "rgb"))
    rgb, sparse = torch.rand(1, 3, 64, 64) * 255, torch.rand(1, 1, 64, 64) * 80
    with torch.no_grad():
        _, feats = enc(torch.cat((rgb, sparse), dim=1))
        cg = backbone._color_guided(rgb, sparse)
    torch.testing.assert_close(feats[-1], cg.encoder_out)


def test_checkpoint_filter_rejects_a_missing_branch() -> None:
    with pytest.raises(InputError, match="no segment encoder"):
        authors_encoder_filter({"rgb_conv_init.0.weight": torch.zeros(1)}, "segment")
    with pytest.raises(InputError, match="branch must be one of"):
        authors_encoder_filter({}, "lidar")
