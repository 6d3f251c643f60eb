"""``semattnet models --params``: every registered model's row has its GMAC at 352x1216, the real-time ones and
the paper's alike."""

from __future__ import annotations

import pytest

import semattnet
from semattnet.models import registry


def test_paper_rows_show_the_gmac_of_a_full_frame(monkeypatch: pytest.MonkeyPatch) -> None:
    """Counted on a 352x64 strip and scaled by the area: a two-branch ablation row (built at width 1/8 here to stay
    fast) shows what a count on the whole 352x1216 frame gives (3.373 GMAC, counted once)."""
    spec = next(s for s in registry._SPECS if s.name == "table2_a")
    small = semattnet.build_model("table2_a", width=0.125).eval()
    monkeypatch.setattr(registry, "build_model", lambda name: small)
    params, gmac, unit = registry._params_and_macs(spec).split()
    assert unit == "GMAC" and float(gmac) == pytest.approx(3.37, abs=0.005)
    assert int(params.replace(",", "")) == sum(p.numel() for p in small.parameters())
