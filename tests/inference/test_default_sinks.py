"""default_sinks: every file sink made by its own options, as predict makes them, in the registry's order."""

from __future__ import annotations

import pytest

from semattnet._errors import InputError
from semattnet.inference.sinks import OutputSettings, PanelOptions, PlyOptions, default_sinks
from semattnet.robotics.sinks import BagOutOptions


def test_the_default_is_the_depth_and_colour_pngs() -> None:
    assert [type(s).__name__ for s in default_sinks()] == ["DepthPngSink", "ColorPngSink"]


def test_settings_and_options_add_their_sinks_in_the_registrys_order() -> None:
    settings = OutputSettings(npy=True, uncertainty=True, max_depth=30.0, top_crop=4)
    sinks = default_sinks(settings, PanelOptions(panel=True), PlyOptions(ply=True))
    names = [type(s).__name__ for s in sinks]
    assert names == [
        "DepthPngSink",
        "ColorPngSink",
        "PlySink",
        "NpySink",
        "UncertaintyPngSink",
        "UncertaintyNpySink",
        "PanelSink",
    ]
    ply = sinks[2]
    assert (ply.max_depth, ply.top_crop) == (30.0, 4)  # type: ignore[attr-defined]
    assert [type(s).__name__ for s in default_sinks(None, PlyOptions(ply=False))] == ["DepthPngSink", "ColorPngSink"]


def test_an_option_that_is_not_a_files_or_given_twice_is_refused() -> None:
    with pytest.raises(InputError, match="each of"):
        default_sinks(None, BagOutOptions())
    with pytest.raises(InputError, match="each of"):
        default_sinks(None, PlyOptions(ply=True), PlyOptions(ply=False))
