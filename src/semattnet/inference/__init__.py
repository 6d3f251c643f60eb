"""Inference on a user's frames: NumPy in / NumPy out at any size (padding to multiples of 32),
and whole folders of files (what ``semattnet predict`` runs)."""

from semattnet.inference.completer import Completion, DepthCompleter
from semattnet.inference.folder import complete_folder
from semattnet.inference.padding import crop_padding, pad_to_multiple

__all__ = ["Completion", "DepthCompleter", "complete_folder", "crop_padding", "pad_to_multiple"]
