"""torch.hub entry points: ``torch.hub.load("<owner>/semattnet", "semattnet", pretrained=True)``.

``pretrained`` is False (fresh weights; keyword arguments are config fields such as
``width=0.25``), True (the released weights, ``semattnet-kitti``) or a weights name, local path or
URL (http(s)://, file://, gdrive://<id>, hf://owner/repo). See ``semattnet.weights.from_pretrained``.
"""

import os
import sys

# The package lives in src/ (src layout): make it importable from a checkout.
_SRC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "src")
if _SRC not in sys.path:
    sys.path.insert(0, _SRC)

dependencies = ["torch", "numpy", "safetensors", "platformdirs"]


def semattnet(pretrained=False, **kwargs):
    """SemAttNet: three-branch backbone with SAMMAFB and CSPN++ refinement (paper Table 2, row g).

    ``pretrained=True`` loads the authors' KITTI weights (Google Drive; needs gdown).
    """
    from semattnet.weights import hub_model

    return hub_model("semattnet", pretrained, **kwargs)


def semattnet_backbone(pretrained=False, **kwargs):
    """The three-branch backbone alone (paper Table 2, row f). The authors released no weights for it."""
    from semattnet.weights import hub_model

    return hub_model("semattnet_backbone", pretrained, **kwargs)
