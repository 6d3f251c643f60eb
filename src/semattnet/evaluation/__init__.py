"""Evaluation: KITTI devkit metrics, scoring models / checkpoints / prediction folders, test submissions,
sparsification curves (AUSE / AURG) of a per-pixel uncertainty."""

from semattnet.evaluation.evaluate import evaluate_checkpoint, evaluate_model, score_folders
from semattnet.evaluation.metrics import KittiMetrics, fill_holes_kitti, image_metrics
from semattnet.evaluation.sparsification import Sparsification, aurg, ause, sparsification_curve
from semattnet.evaluation.submission import SubmissionError, write_submission, write_submission_files

__all__ = [
    "KittiMetrics",
    "Sparsification",
    "SubmissionError",
    "aurg",
    "ause",
    "evaluate_checkpoint",
    "evaluate_model",
    "fill_holes_kitti",
    "image_metrics",
    "score_folders",
    "sparsification_curve",
    "write_submission",
    "write_submission_files",
]
