"""Every Python and shell block of README.md and docs/ runs on tiny inputs, or says why not."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.docs._blocks import REPO, all_blocks, markdown_files, parse_blocks, run_page

#: At least this share of the counted blocks must run in the default suite (issue 24).
MIN_RUN_SHARE = 0.90


def block_counts() -> tuple[int, int]:
    """(blocks run, blocks counted) over README.md and docs/."""
    counted = [b for b in all_blocks() if b.counted]
    return sum(b.not_run is None for b in counted), len(counted)


def coverage_line() -> str:
    ran, total = block_counts()
    return f"{ran} of {total} blocks run ({100 * ran / max(total, 1):.1f} %)"


def _pages() -> list[Path]:
    return [p for p in markdown_files() if any(b.counted and b.not_run is None for b in parse_blocks(p))]


#: Pages whose blocks take 15 s to minutes on two cores (they train, adapt, convert or serve): ``make test-slow``.
#: The README, the new-rig guides (own camera, the generalist, the ROS 2 node) and the quick pages run by default.
SLOW_PAGES = {
    "docs/datasets/nyuv2.md",
    "docs/datasets/void.md",
    "docs/guides/adapt.md",
    "docs/guides/data.md",
    "docs/guides/demo.md",
    "docs/guides/robots.md",
    "docs/guides/safety.md",
    "docs/guides/torchrun.md",
    "docs/guides/training.md",
    "docs/guides/weights.md",
}


def _page_params() -> list[object]:
    return [
        pytest.param(p, marks=pytest.mark.slow) if p.relative_to(REPO).as_posix() in SLOW_PAGES else p for p in _pages()
    ]


@pytest.mark.parametrize("page", _page_params(), ids=lambda p: str(p.relative_to(REPO)))
def test_page_blocks_run(page: Path, docs_workspace: Path, page_env: dict[str, str], tmp_path: Path) -> None:
    work = tmp_path / "work"
    shutil.copytree(docs_workspace, work, symlinks=True)
    blocks = parse_blocks(page)
    ran = run_page(blocks, work, page_env)
    assert ran == sum(b.counted and b.not_run is None for b in blocks)


def test_share_of_blocks_run() -> None:
    ran, total = block_counts()
    print(coverage_line())
    assert total > 0
    assert ran / total >= MIN_RUN_SHARE, f"only {coverage_line()}; at least {MIN_RUN_SHARE:.0%} must run"


def test_not_run_blocks_give_a_reason() -> None:
    empty = [b.where for b in all_blocks() if b.not_run is not None and not b.not_run.strip()]
    assert not empty, f"not-run markers without a reason: {empty}"


def test_every_block_names_its_language() -> None:
    """An untagged fence could hide a shell command from the collector."""
    bare = [b.where for b in all_blocks() if not b.lang]
    assert not bare, f"fenced blocks without a language (use text for output): {bare}"
