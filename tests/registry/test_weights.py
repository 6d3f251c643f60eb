"""Every released weights record (:func:`semattnet.weights.list_pretrained`): the schema, the parameter count of
its architecture, and for the weights shipped inside the package (loadable offline) the model they build, a
tampered checksum refused and the outputs on a fixed input; the others are metadata only (no network: offline
mode must refuse them in one line)."""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from typing import ClassVar
from urllib.parse import urlparse

import pytest
import torch

from semattnet.models.registry import MODELS
from semattnet.weights import (
    FORMATS,
    CheckpointError,
    OfflineError,
    PretrainedWeights,
    from_pretrained,
    get_weights,
    list_pretrained,
)
from semattnet.weights.resolve import packed_file
from tests._base import RegistryTester
from tests._helpers import random_inputs

UNITS = ("_mm", "_m", "_per_km", "_pct")
INPUT_KEYS = {"rgb", "semantic", "sparse", "size_multiple"}


@dataclass(frozen=True)
class WeightsFixture:
    """``shipped``: the file is inside the package (loads offline); ``mean``/``std``: the refined depth's on
    ``random_inputs(b=1, h=32, w=64)`` (recorded when the weights were registered), for shipped weights."""

    shipped: bool
    mean: float | None = None
    std: float | None = None


@cache
def loaded(name: str) -> torch.nn.Module:
    return from_pretrained(name).eval()


class TestWeights(RegistryTester[WeightsFixture]):
    kind = "weights"
    fixtures: ClassVar[Mapping[str, WeightsFixture]] = {
        "semattnet-kitti": WeightsFixture(shipped=False),
        "semattnet-demo-ref-seed0": WeightsFixture(shipped=True, mean=10.6878, std=4.5891),
        "semattnet-demo-ref-seed1": WeightsFixture(shipped=True, mean=15.3220, std=7.8854),
        "semattnet-demo-ref-robust-seed0": WeightsFixture(shipped=True, mean=15.1961, std=6.6165),
        "semattnet-demo-ref-robust-seed1": WeightsFixture(shipped=True, mean=19.5696, std=8.2247),
        "semattnet-rt-l-demo-seed0": WeightsFixture(shipped=True, mean=19.0104, std=8.6174),
        "semattnet-rt-l-demo-seed1": WeightsFixture(shipped=True, mean=24.6099, std=8.7986),
        "semattnet-rt-md-demo-seed0": WeightsFixture(shipped=True, mean=23.5374, std=8.7159),
        "semattnet-rt-md-demo-seed1": WeightsFixture(shipped=True, mean=27.5427, std=9.7617),
        "semattnet-rt-generalist": WeightsFixture(shipped=True, mean=18.8683, std=10.4790),
        "semattnet-rt-half-generalist": WeightsFixture(shipped=True, mean=17.8641, std=11.5327),
        "semattnet-half-generalist": WeightsFixture(shipped=True, mean=17.2048, std=9.6906),
        "semattnet-generalist": WeightsFixture(shipped=True, mean=18.0728, std=9.8995),
    }

    @classmethod
    def entries(cls) -> list[str]:
        return list_pretrained()

    def test_smoke(self, entry: str) -> None:
        """The record's schema; a shipped one builds its model offline."""
        fx, w = self.fixture(entry), get_weights(entry)
        assert isinstance(w, PretrainedWeights) and w.name == entry and w.to_dict()["name"] == entry
        assert re.fullmatch(r"[a-z0-9]+(-[a-z0-9]+)*", entry) and w.arch in MODELS
        assert w.model_config() == MODELS[w.arch].config.replace(**w.config)  # the overrides are config fields
        assert w.urls, "at least one URL"
        for url in w.urls:
            scheme = urlparse(url).scheme
            assert scheme in ("https", "http", "gdrive", "hf") or (scheme == "file" and w.format == "packed"), url
            assert scheme != "gdrive" or re.fullmatch(r"gdrive://[\w-]{10,}", url)
        assert w.file_name and "/" not in w.file_name and w.format in FORMATS and w.license.strip()
        assert w.sha256 is None or re.fullmatch(r"[0-9a-f]{64}", w.sha256)
        assert w.size_bytes is None or (isinstance(w.size_bytes, int) and w.size_bytes > 0)
        assert w.sha256 is not None or "trust on first use" in w.notes  # say what happens without a checksum
        assert INPUT_KEYS <= set(w.preprocessing) and w.preprocessing["size_multiple"] == 32
        assert w.doi is None or re.fullmatch(r"10\.\d{4,}/\S+", w.doi)
        assert w.paper and w.source
        assert (w.format == "packed" and w.urls[0].startswith("file:")) == fx.shipped
        if fx.shipped:
            assert packed_file(w).stat().st_size == w.size_bytes
            assert loaded(entry).config == w.model_config()

    def test_cardinality(self, entry: str) -> None:
        """The parameter count the record states is its architecture's (and the loaded model's)."""
        fx, w = self.fixture(entry), get_weights(entry)
        with torch.device("meta"):  # no memory for the 361 M parameters
            model = w.build()
        assert sum(p.numel() for p in model.parameters()) == w.num_params
        if fx.shipped:
            assert sum(p.numel() for p in loaded(entry).parameters()) == w.num_params

    def test_exception(self, entry: str, monkeypatch: pytest.MonkeyPatch) -> None:
        """Offline, a download is refused in one line; a shipped file whose sha256 differs is refused."""
        fx, w = self.fixture(entry), get_weights(entry)
        if fx.shipped:
            fake = PretrainedWeights(**{**w.to_dict(), "name": "tampered", "sha256": "0" * 64})
            with pytest.raises(CheckpointError, match=r"weights 'tampered': .*does not match its sha256 0000"):
                from_pretrained(fake)
        else:
            monkeypatch.setenv("SEMATTNET_OFFLINE", "1")
            with pytest.raises(OfflineError, match=f"offline mode .* {re.escape(w.file_name)} is not cached") as err:
                from_pretrained(entry)
            assert "\n" not in str(err.value)

    def test_numerics(self, entry: str) -> None:
        """Shipped: the outputs on a fixed input as recorded; the others: the paper's metrics, with units."""
        fx, w = self.fixture(entry), get_weights(entry)
        assert w.paper_metrics
        for split, metrics in w.paper_metrics.items():
            assert re.fullmatch(r"[a-z0-9]+/[a-z0-9-]+", split), split
            for key, value in metrics.items():
                assert key.endswith(UNITS), f"{split}/{key}: metric keys carry their unit"
                assert isinstance(value, float) and value > 0
        if fx.shipped:
            with torch.inference_mode():
                depth = loaded(entry)(**random_inputs(b=1, h=32, w=64)).refined_depth
            assert torch.isfinite(depth).all()
            assert float(depth.mean()) == pytest.approx(fx.mean, rel=1e-3)
            assert float(depth.std()) == pytest.approx(fx.std, rel=1e-3)
