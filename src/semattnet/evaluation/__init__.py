"""Evaluation: KITTI devkit metrics, scoring completers over a dataset's split (through the one frame loop) and
prediction folders, test submissions, sparsification curves (AUSE / AURG) of a per-pixel uncertainty."""

from semattnet.evaluation.evaluate import EvalOutputs, EvalSplit, Evaluation, evaluate_split, score_folders
from semattnet.evaluation.metrics import KittiMetrics, fill_holes_kitti, image_metrics
from semattnet.evaluation.protocols import eval_source, protocol_metrics
from semattnet.evaluation.sink import MetricsSink
from semattnet.evaluation.sparsification import Sparsification, aurg, ause, sparsification_curve
from semattnet.evaluation.submission import SubmissionError, write_submission, write_submission_files

__all__ = [
    "EvalOutputs",
    "EvalSplit",
    "Evaluation",
    "KittiMetrics",
    "MetricsSink",
    "Sparsification",
    "SubmissionError",
    "aurg",
    "ause",
    "eval_source",
    "evaluate_split",
    "fill_holes_kitti",
    "image_metrics",
    "protocol_metrics",
    "score_folders",
    "sparsification_curve",
    "write_submission",
    "write_submission_files",
]
