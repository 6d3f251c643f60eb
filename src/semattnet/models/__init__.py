"""The SemAttNet network (paper Sec. III), one module per part of the architecture.

* :mod:`.config` typed options, :mod:`.registry` named variants (paper model, Table 2 ablations).
* :mod:`.layers` conv/BN building blocks; :mod:`.attention` SAMMAFB (eqs. 1-4);
  :mod:`.fusion` feature fusion of the branches (SAMMAFB / concat / add).
* :mod:`.branches` colour-, semantic- and depth-guided branches (Sec. III-B);
  :mod:`.backbone` the three branches and :mod:`.confidence_fusion` (eq. 12).
* :mod:`.refinement` CSPN++ with atrous propagation (Sec. III-C) over :mod:`.propagation` (eq. 13);
  :mod:`.semattnet` the full model; :mod:`.outputs` its typed result.
* :mod:`.encoders` the branch encoders behind one interface and their registry (the authors' ResNet first);
  :mod:`.rt` the real-time variants (SemAttNet-RT) built on the light ones.
* :mod:`.checks` input validation; :mod:`.bn_folding` BatchNorm folding for inference; :mod:`.macs` MAC counts.
"""

from semattnet.models.backbone import SemAttNetBackbone
from semattnet.models.config import SemAttNetConfig
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.registry import MODELS, build_model, describe_models, list_models
from semattnet.models.semattnet import SemAttNet

__all__ = [
    "MODELS",
    "DepthCompletionOutput",
    "SemAttNet",
    "SemAttNetBackbone",
    "SemAttNetConfig",
    "build_model",
    "describe_models",
    "list_models",
]
