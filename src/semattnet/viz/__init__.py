"""Pictures: depth colour maps, error maps, per-branch panels, training curves, the HTML report."""

from semattnet.viz.depth import colorize_depth, confidence_image, error_map
from semattnet.viz.panels import branch_panel, save_panel

__all__ = ["branch_panel", "colorize_depth", "confidence_image", "error_map", "save_panel"]
