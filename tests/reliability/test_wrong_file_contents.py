"""A file that holds something other than it should is refused in one line naming it: a state dict of another
model (``.pt``, ``.safetensors``, ``.pth.tar``), by ``from_pretrained`` and by ``convert`` (which changes nothing),
and a PCD header whose WIDTH x HEIGHT is not its number of POINTS."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from semattnet._errors import DataError
from tests.reliability._helpers import cli as _cli
from tests.reliability._helpers import one_line as _one_line


@pytest.mark.parametrize("fmt", ["pt", "safetensors", "pth.tar"])
def test_not_a_semattnet_state_dict_names_the_file(tmp_path: Path, fmt: str) -> None:
    from safetensors.torch import save_file

    import semattnet

    path = tmp_path / f"other.{fmt}"
    sd = {"conv.weight": torch.zeros(2, 2, 3, 3)}
    save_file(sd, str(path)) if fmt == "safetensors" else torch.save({"state_dict": sd}, path)
    msg = _one_line(lambda: semattnet.from_pretrained(path, progress=False))
    assert str(path) in msg and "not a SemAttNet state dict" in msg, msg
    code, msg = _cli(tmp_path, "convert", path, tmp_path / "o.safetensors")
    assert code == 1 and str(path) in msg, msg


@pytest.mark.parametrize(("width", "height"), [("99999999", "99999999"), ("2", "1"), ("0", "1"), ("x", "1")])
def test_pcd_width_times_height_must_be_points(tmp_path: Path, width: str, height: str) -> None:
    from semattnet.geometry import read_points

    path = tmp_path / "c.pcd"
    path.write_text(
        f"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {width}\nHEIGHT {height}\n"
        "POINTS 1\nDATA ascii\n5 0 0\n"
    )
    assert "c.pcd: PCD WIDTH" in _one_line(lambda: read_points(path), DataError)
