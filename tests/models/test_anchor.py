"""The classical completion's own steps (models.anchor): the fast row-then-column extension against the plain one."""

from __future__ import annotations

import pytest
import torch

from semattnet.models import anchor


def _plain(x: torch.Tensor) -> torch.Tensor:
    """The extension step as written first: every row, then every column, whatever is filled."""
    return anchor._extend_along(anchor._extend_along(x, -1), -2)


@pytest.mark.parametrize("seed", range(40))
def test_the_row_then_column_extension_equals_extending_every_row_and_column(seed: int) -> None:
    g = torch.Generator().manual_seed(seed)
    b, h, w = (
        1 + seed % 2,
        1 + int(torch.randint(0, 30, (1,), generator=g)),
        1 + int(torch.randint(0, 30, (1,), generator=g)),
    )
    share = float(torch.rand(1, generator=g)) ** 3
    x = torch.rand(b, 1, h, w, generator=g) * (torch.rand(b, 1, h, w, generator=g) < share)
    if seed % 3 == 0:
        x[..., : h // 2, :] = 0  # whole rows empty: filled from the nearest filled row
    if seed % 5 == 0:
        x[0] = 0  # an image without any value stays empty
    assert torch.equal(anchor._extend_rows_then_columns(x), _plain(x))


def test_ties_take_the_pixel_before_and_an_empty_image_stays_empty() -> None:
    x = torch.tensor([[0.0, 2.0, 0.0, 0.0, 5.0, 0.0]]).view(1, 1, 1, 6)
    assert anchor._extend_rows_then_columns(x).flatten().tolist() == [2.0, 2.0, 2.0, 5.0, 5.0, 5.0]
    col = torch.tensor([0.0, 3.0, 0.0, 7.0, 0.0]).view(1, 1, 5, 1).expand(1, 1, 5, 2).clone()
    assert anchor._extend_rows_then_columns(col)[0, 0, :, 0].tolist() == [3.0, 3.0, 3.0, 7.0, 7.0]
    assert not anchor._extend_rows_then_columns(torch.zeros(1, 1, 4, 4)).any()
