"""Evaluation: KITTI devkit metrics, scoring models / checkpoints / prediction folders, test submissions."""

from semattnet.evaluation.evaluate import evaluate_checkpoint, evaluate_model, score_folders
from semattnet.evaluation.metrics import KittiMetrics, fill_holes_kitti, image_metrics
from semattnet.evaluation.submission import SubmissionError, write_submission, write_submission_files

__all__ = [
    "KittiMetrics",
    "SubmissionError",
    "evaluate_checkpoint",
    "evaluate_model",
    "fill_holes_kitti",
    "image_metrics",
    "score_folders",
    "write_submission",
    "write_submission_files",
]
