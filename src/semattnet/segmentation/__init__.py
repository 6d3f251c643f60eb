"""Semantic maps for the semantic-guided branch: any Cityscapes segmenter (TorchScript, ONNX,
torchvision) run over an image tree, written as Cityscapes-coloured PNGs.
The palette itself is :mod:`semattnet.palette`."""

from semattnet.segmentation.segmenter import Segmenter, SegmentSummary, load_segmenter, segment_folder

__all__ = ["SegmentSummary", "Segmenter", "load_segmenter", "segment_folder"]
