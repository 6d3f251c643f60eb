"""A stand-in for a checkout of the authors' repository, written by the tests (never their code).

``model.py`` defines ``A_CSPN_plus_plus(args)`` with their interface (``forward({"rgb", "d", "semantic"})`` ->
their 8-tuple) around our model at width 0.125 (so its state dict is ours at that width); it imports
``basic.py`` beside it as theirs does (``from basic import *``), which checks the isolated import.
"""

from __future__ import annotations

from pathlib import Path

#: Our width inside the stand-in: the benchmarks' ``--width`` must be the same.
WIDTH = 0.125

_BASIC = f"WIDTH = {WIDTH}\n"

_MODEL = """
from basic import *  # noqa: F403  (as their model.py starts)

import semattnet
from torch import nn


class A_CSPN_plus_plus(nn.Module):
    def __init__(self, args):
        super().__init__()
        assert args.network_model == "sem_att" and args.dilation_rate == 2, args
        inner = semattnet.build_model("semattnet", width=WIDTH)  # noqa: F405
        for name, child in inner.named_children():  # the same state-dict names as ours
            self.add_module(name, child)
        object.__setattr__(self, "inner", inner)

    def train(self, mode=True):
        super().train(mode)
        self.inner.training = mode
        return self

    def forward(self, input):
        o = self.inner(rgb=input["rgb"], semantic=input["semantic"], sparse=input["d"])
        return (o.color_conf, o.semantic_conf, o.guided_conf, o.color_depth, o.semantic_depth, o.guided_depth,
                o.refined_s2_depth, o.refined_depth)
"""


def write_fake_authors(folder: Path) -> Path:
    """The stand-in checkout in ``folder`` (created); returns it."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "basic.py").write_text(_BASIC)
    (folder / "model.py").write_text(_MODEL)
    return folder
