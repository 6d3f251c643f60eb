"""The ``--dataset NAME`` option every data command takes (:mod:`semattnet.data.datasets`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import click

from semattnet.data.datasets import DATASETS, DEFAULT_DATASET

__all__ = ["dataset_option"]


_F = TypeVar("_F", bound=Callable[..., object])


def dataset_option(help_text: str = "The dataset and its protocol.") -> Callable[[_F], _F]:
    """``--dataset`` (default ``kitti-dc``; an unknown name lists the valid ones)."""
    return click.option(
        "--dataset", type=click.Choice(list(DATASETS)), default=DEFAULT_DATASET, show_default=True, help=help_text
    )
