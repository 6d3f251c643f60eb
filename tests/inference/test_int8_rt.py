"""The int8 engine on a real-time model (models/rt): its propagation, stems and heads stay float32."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest
import torch

import semattnet
from semattnet.inference.backends import openvino_int8 as int8_module
from semattnet.inference.backends import optimize_for_inference
from tests._helpers import random_inputs

SIZE = (64, 96)


@pytest.mark.slow  # ONNX export, OpenVINO conversion and NNCF of a real-time model: about 20 s on 2 busy cores
@pytest.mark.skipif(
    importlib.util.find_spec("openvino") is None or importlib.util.find_spec("nncf") is None,
    reason="int8 needs openvino and nncf (pip install 'semattnet[openvino]')",
)
def test_real_time_model_quantises_only_its_branches(tmp_path: Path) -> None:
    """Every KEEP_FLOAT_RT pattern names nodes of the real-time graph, and no FakeQuantize feeds a node outside
    the branches (the propagation's sums and products, the heads, the upsampling stay float32)."""
    import openvino as ov

    torch.manual_seed(0)
    model = semattnet.build_model("semattnet_rt_s").eval()
    engine = optimize_for_inference(
        model, backend="openvino", precision="int8", size=SIZE, cache_dir=tmp_path, calibration_frames=2
    )
    assert torch.isfinite(engine(**random_inputs(b=1, h=SIZE[0], w=SIZE[1])).refined_depth).all()
    f32 = ov.Core().read_model(str(next(tmp_path.glob("engines/*/model.xml"))))
    names = [op.get_friendly_name() for op in f32.get_ordered_ops()]
    assert all(any(re.match(p, n) for n in names) for p in int8_module.KEEP_FLOAT_RT)
    int8 = ov.Core().read_model(str(next(tmp_path.glob("engines/*/int8-*/model.xml"))))
    quantised = {
        t.get_node().get_friendly_name()
        for op in int8.get_ordered_ops()
        if op.get_type_name() == "FakeQuantize"
        for port in op.outputs()
        for t in port.get_target_inputs()
        if t.get_node().get_type_name() != "ShapeOf"
    }
    assert quantised and all("_branch/" in n for n in quantised), sorted(n for n in quantised if "_branch/" not in n)
    assert not [n for n in quantised if re.match(r".*_branch/(head|encoder/stem/stem\.0)/", n)]
