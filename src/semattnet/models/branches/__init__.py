"""The three branches of the backbone (paper Sec. III-B): colour-, semantic- and depth-guided.

Each branch is a mixin of :class:`~semattnet.models.backbone.SemAttNetBackbone`: it registers its
layers directly on the backbone, so that parameter names are the authors' flat keys
(``rgb_encoder_layer1.conv1.weight``, ``segment_decoder_layer3.0.weight``, ...), and provides
the branch's forward pass as a method.
"""

from semattnet.models.branches.color_guided import ColorGuidedBranch, ColorGuidedFeatures
from semattnet.models.branches.depth_guided import DepthGuidedBranch, DepthGuidedFeatures
from semattnet.models.branches.semantic_guided import SemanticGuidedBranch, SemanticGuidedFeatures

__all__ = [
    "ColorGuidedBranch",
    "ColorGuidedFeatures",
    "DepthGuidedBranch",
    "DepthGuidedFeatures",
    "SemanticGuidedBranch",
    "SemanticGuidedFeatures",
]
