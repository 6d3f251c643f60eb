"""Inference on a user's frames: NumPy in / NumPy out at any size (padding to multiples of 32),
and the one frame loop from any frame source into output sinks (what ``semattnet predict`` runs)."""

from semattnet.inference.backends import EngineSpec
from semattnet.inference.completer import Completion, DepthCompleter, load_completer
from semattnet.inference.contract import CompleterFactory
from semattnet.inference.folder import complete_folder
from semattnet.inference.options import OutputSpec, RunOptions
from semattnet.inference.padding import crop_padding, pad_to_multiple
from semattnet.inference.pipeline import RunPlan, check_frames, complete_frames
from semattnet.inference.timing import StageTimes

__all__ = [
    "CompleterFactory",
    "Completion",
    "DepthCompleter",
    "EngineSpec",
    "OutputSpec",
    "RunOptions",
    "RunPlan",
    "StageTimes",
    "check_frames",
    "complete_folder",
    "complete_frames",
    "crop_padding",
    "load_completer",
    "pad_to_multiple",
]
