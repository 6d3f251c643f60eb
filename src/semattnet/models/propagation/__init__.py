"""CSPN++ propagation with atrous neighbourhoods (paper Sec. III-C, eq. 13), in its four forms.

* :mod:`.affinity`: guidance -> normalised k x k kernel (eq. 13, or a convex one); sparse depth at 1/2 scale.
* :mod:`.shifted`: the default form, for training and inference (autograd, in-place taps).
* :mod:`.cpu_kernel`: a fused C++ loop for float32 CPU inference, compiled on first use.
* :mod:`.export`: plain tensor ops for ONNX / TorchScript tracing / ``torch.compile``.
* :mod:`.reference`: the authors' pad-and-sum, the naive reference of tests and benchmarks.

All forms compute the same update; the tests compare each with a per-pixel loop.
"""

from semattnet.models.propagation.affinity import (
    AFFINITY_FORMS,
    AffinityForm,
    AffinityHead,
    convex_affinity,
    cspn_affinity,
    downsample_sparse,
    normalise_affinity,
)
from semattnet.models.propagation.reference import propagate_pad_and_sum
from semattnet.models.propagation.shifted import propagate, propagate_shifted, shift_affinity

__all__ = [
    "AFFINITY_FORMS",
    "AffinityForm",
    "AffinityHead",
    "convex_affinity",
    "cspn_affinity",
    "downsample_sparse",
    "normalise_affinity",
    "propagate",
    "propagate_pad_and_sum",
    "propagate_shifted",
    "shift_affinity",
]
