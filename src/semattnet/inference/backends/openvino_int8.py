"""int8 OpenVINO IR by NNCF post-training quantisation (``optimize_for_inference(..., precision="int8")``).

The float32 IR of the network (the cached export, without the CSPN++ propagation, which stays
float32 in the fused kernel) is quantised once per calibration with ``nncf.quantize``: NNCF runs
the calibration frames (:mod:`semattnet.inference.backends.calibration`) through it, sets the
ranges of 8-bit weights (per channel, symmetric) and activations, and inserts FakeQuantize
nodes, which OpenVINO's CPU plugin executes as int8 convolutions (VNNI where the CPU has it).
The quantised IR is cached beside the float32 one, under ``int8-<calibration key>/``; writes are
staged in a temporary folder and renamed into place, so a killed run leaves no partial IR.

``KEEP_FLOAT``: the layers left in float32 (NNCF's ``ignored_scope``), chosen by measurement on the shipped
reference checkpoints (``benchmarks/bench_int8_accuracy.py``; the search used their training scenes, never the
held-out ones): the stems, whose inputs are raw sparse depth in metres (an 8-bit grid over 0..80 m would be
0.3 m coarse); the confidence fusion, whose inputs are the branches' depths in metres (quantising them cost
+5 % iMAE alone); the three branch output heads (depth and confidence, 2 channels each: quantised, they move
the fusion weights, about +1 % iMAE); and the refinement heads, whose affinities and masks the propagation
multiplies 36 times.

``KEEP_FLOAT_RT``: the same rule for the real-time models (:mod:`semattnet.models.rt`), whose graph holds their
propagation (the reduced-resolution CSPN++ and the last full-resolution steps, as plain tensor operations): the
first convolution of each branch's stem (raw sparse depth in), the branch output heads, the refinement heads, the
learned upsamplings (of the affinities, and the convex weights of the depth), every operation of the model's own
forward outside the branches (the propagation's sums and products, the confidence fusion's softmax), and the
bilinear upsamplings of the outputs to full resolution (named after them: one of them starts the last
propagation steps). Measured on
``semattnet_rt_s`` trained by ``benchmarks/frontier.py`` (the demo reference recipe, seed 0) on the demo's 16
held-out scenes, int8 against float32: with these layers float, RMSE +0.1 %, MAE -0.1 %, iRMSE +0.4 %, iMAE
+0.2 %; with only :data:`KEEP_FLOAT`, +3.5 %, +22 %, +38 % and +55 %. They apply to a graph without refinement
head outputs only (:func:`keep_float`), so the paper model's quantisation is unchanged.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from types import ModuleType
from typing import Any

from semattnet._utils.extras import require
from semattnet.inference.backends._base import LogFn
from semattnet.inference.backends._export_cache import intact, record_digest
from semattnet.inference.backends.calibration import Calibration

__all__ = ["KEEP_FLOAT", "KEEP_FLOAT_RT", "keep_float", "name_layers", "quantized_ir"]

#: Regular expressions over the IR's node names of the layers kept in float32 (module docstring).
KEEP_FLOAT: tuple[str, ...] = (
    r".*conv_init.*",  # the branch stems: raw sparse depth (and colours) in
    r"confidence_fusion/.*",  # the branch depths in metres, blended by the softmax weights (name_layers)
    r"/rgb_decoder_output/.*",  # the branch output heads: depth + confidence (transposed: name_layers)
    r"/segment_decoder_layer6/.*",
    r"/decoder_layer6/.*",
    r"refinement_heads/.*",  # the affinity, kernel-confidence and mask heads of both stages (name_layers)
)
#: Regular expressions over the IR's node names of the real-time models' layers kept in float32 (module docstring).
KEEP_FLOAT_RT: tuple[str, ...] = (
    r".*_branch/encoder/stem/stem\.0/.*",  # each branch's first convolution: raw sparse depth (and colours) in
    r".*_branch/head/.*",  # the branch output heads: depth + confidence
    r"/model/(Conv|convex|upsample(\.0)?)(_\d+)?/.*",  # refinement heads (a conv a stage), learned upsamplings
    r"/model/[A-Za-z]+(_\d+)?$",  # the model's own operations: the propagation, the fusion's softmax, the resizes
    r"(color|semantic|guided)_(depth|conf)$",  # the outputs' upsamplings to full resolution (metres, weights)
    r"(fused|refined_s2)_depth$",  # refined_s2_depth's starts the last full-resolution propagation steps
)
#: The graph outputs whose heads ``name_layers`` names ``refinement_heads/...``.
_HEAD_OUTPUTS = ("refinement.heads",)  # and refinement.heads_s2


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _consumers(op: Any) -> list[Any]:
    return [t.get_node() for port in op.outputs() for t in port.get_target_inputs()]


def _name_heads(model: Any) -> None:
    """``refinement_heads/<name>``: every node from a refinement head output back to its convolution (one
    convolution per stage serves all the heads: :func:`semattnet.models.layers.stacked_heads`)."""
    todo = [
        out.get_node().input_value(0).get_node()
        for out in model.outputs
        if any(n.startswith(_HEAD_OUTPUTS) for n in out.get_names())
    ]
    seen: set[str] = set()
    while todo:
        op = todo.pop()
        name = op.get_friendly_name()
        if name in seen or op.get_type_name() in ("Parameter", "Constant"):
            continue
        seen.add(name)
        if not name.startswith("refinement_heads/"):
            op.set_friendly_name(f"refinement_heads/{name}")
        if op.get_type_name() != "Convolution":  # the heads' convolution is where they begin
            todo.extend(op.input_value(i).get_node() for i in range(op.get_input_size()))


def name_layers(model: Any) -> None:
    """Name the nodes of ``model`` (an ``ov.Model``) that :data:`KEEP_FLOAT` needs but the ONNX export leaves
    unnamed.

    * Transposed convolutions: OpenVINO's ONNX reader names them ``ConvolutionBackpropData_<n>`` and puts the
      layer's name on the bias ``Add`` after them; they become ``<that name>/WithoutBiases``, as the plain
      convolutions are.
    * The confidence fusion (:func:`semattnet.models.confidence_fusion.confidence_fusion`, a function, not a
      module): the ``Multiply`` of the softmax weights by the concatenated branch depths, that ``Concat`` and the
      ``ReduceSum`` after it become ``confidence_fusion/{depths,weighted,sum}``.
    * The refinement heads (one convolution per stage, then a split: not one module each) become
      ``refinement_heads/<name>``.
    """
    _name_heads(model)
    for op in model.get_ordered_ops():
        kind = op.get_type_name()
        if kind == "ConvolutionBackpropData" and "/" not in op.get_friendly_name():
            after = _consumers(op)
            if len(after) == 1 and after[0].get_type_name() == "Add":
                op.set_friendly_name(f"{after[0].get_friendly_name()}/WithoutBiases")
        elif kind == "Softmax":
            for mul in (n for n in _consumers(op) if n.get_type_name() == "Multiply"):
                ins = [mul.input_value(i).get_node() for i in range(2)]
                depths = [n for n in ins if n.get_type_name() == "Concat"]
                sums = [n for n in _consumers(mul) if n.get_type_name() == "ReduceSum"]
                if len(depths) == 1 and len(sums) == 1:
                    for node, part in ((depths[0], "depths"), (mul, "weighted"), (sums[0], "sum")):
                        node.set_friendly_name(f"confidence_fusion/{part}")


def keep_float(model: Any) -> list[str]:
    """The patterns of the layers of ``model`` (an ``ov.Model``) kept in float32: :data:`KEEP_FLOAT`, and for a graph
    that holds its own propagation (no refinement head outputs: a real-time model) :data:`KEEP_FLOAT_RT`."""
    heads = any(n.startswith(_HEAD_OUTPUTS) for out in model.outputs for n in out.get_names())
    return [*KEEP_FLOAT, *(() if heads else KEEP_FLOAT_RT)]


def quantized_ir(ov: ModuleType, xml: Path, calibration: Calibration, log: LogFn | None = None) -> Path:
    """``<folder of xml>/int8-<calibration.key>/model.xml``: the IR ``xml`` quantised on ``calibration`` by ``ov``
    (computed once; later calls return the cached file)."""
    target = xml.parent / f"int8-{calibration.key}"
    out = target / "model.xml"
    if intact(out, log) and intact(out.with_suffix(".bin"), log):  # verified, not trusted
        return out
    shutil.rmtree(target, ignore_errors=True)  # a damaged or unrecorded copy: quantised again
    nncf = require("nncf", "int8 quantisation")
    if log is not None:
        log(f"quantising to int8 on {calibration.description} (once; cached in {target}) ...")
    model = ov.Core().read_model(str(xml))
    name_layers(model)
    names = [next(n for n in port.get_names() if n in ("rgb", "semantic", "sparse")) for port in model.inputs]
    feeds = [{n: feed[n] for n in names} for feed in calibration.feeds()]
    quantized = nncf.quantize(
        model,
        nncf.Dataset(feeds),
        preset=nncf.QuantizationPreset.MIXED,  # asymmetric activations: ReLU outputs and raw inputs are not centred
        subset_size=len(feeds),
        ignored_scope=nncf.IgnoredScope(patterns=keep_float(model), validate=False),
    )
    from semattnet._utils.outputs import clean_stale_stages

    clean_stale_stages(target.parent, f".{target.name}.p")  # what killed quantisations left
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.p{os.getpid()}.", dir=target.parent))
    try:
        ov.save_model(quantized, str(staging / "model.xml"), compress_to_fp16=False)
        for part in ("model.xml", "model.bin"):
            record_digest(staging / part)
        staging.chmod(0o777 & ~_umask())  # a plain folder's mode, not mkdtemp's 0o700
        os.replace(staging, target)  # another process may have finished first: then keep its copy
    except OSError:
        if not out.is_file():
            raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out
