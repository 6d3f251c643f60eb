"""Bad input to every command: a one-line error naming the file or option, never a traceback,
and the user's folder unchanged (every file hashed before and after)."""

from __future__ import annotations

import hashlib
import os
import stat
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import write_depth, write_image
from semattnet.palette import ids_to_colors


def _tree(root: Path) -> None:
    """A user's folder: frames, a semantic map, a JPEG-like semantic map, a corrupt PNG, a file."""
    rng = np.random.default_rng(0)
    for d in ("rgb", "sparse", "sem", "badsem", "gt", "pred", "ro"):
        (root / d).mkdir()
    for name in ("a", "b"):
        write_image(root / "rgb" / f"{name}.png", rng.integers(0, 255, (32, 48, 3), dtype=np.uint8))
        write_depth(root / "sparse" / f"{name}.png", rng.uniform(0, 50, (32, 48)) * (rng.random((32, 48)) < 0.1))
        write_image(root / "sem" / f"{name}.png", ids_to_colors(rng.integers(0, 19, (32, 48)).astype(np.uint8)))
        write_image(root / "badsem" / f"{name}.png", rng.integers(0, 255, (32, 48, 3), dtype=np.uint8))
        write_depth(root / "gt" / f"{name}.png", rng.uniform(1, 50, (32, 48)))
        write_depth(root / "pred" / f"{name}.png", rng.uniform(1, 50, (32, 48)))
    (root / "bad").mkdir()
    (root / "bad" / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 40)
    (root / "afile").write_text("a regular file")
    (root / "existing.json").write_text("{}")
    (root / "out").mkdir()
    write_image(root / "out" / "a_color.png", np.zeros((4, 4, 3), np.uint8))
    (root / "ro" / "keep.txt").write_text("x")
    os.chmod(root / "ro", stat.S_IRUSR | stat.S_IXUSR)


def _hashes(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


P = "predict --method classical --rgb {t}/rgb --sparse {t}/sparse"
# (args, exit code, a fragment the message must contain)
CASES = [
    # predict
    (P + " --out {t}/rgb", 1, "input folder"),
    (P + " --out {t}/rgb/sub", 1, "input folder"),
    (P + " --out {t}/rgb --overwrite", 1, "input folder"),
    (P + " --out {t}/out", 1, "a_color.png exists"),
    (P + " --out {t}/afile/x", 1, "afile"),
    (P + " --out {t}/ro/x", 1, "ro"),
    (P + " --semantic {t}/badsem --out {t}/new", 1, "outside the Cityscapes palette"),
    (P + " --out {t}/new --max-depth nan", 2, "--max-depth"),
    (P + " --out {t}/new --max-depth -3", 2, "--max-depth"),
    (P + " --out {t}/new --top-crop -1", 2, "--top-crop"),
    ("predict --method classical --rgb {t}/bad/corrupt.png --sparse {t}/sparse/a.png --out {t}/new", 1, "corrupt.png"),
    ("predict --method classical --rgb {t}/rgb/a.png --sparse {t}/bad/corrupt.png --out {t}/new", 1, "corrupt.png"),
    ("predict --method classical --rgb {t}/rgb/a.png --sparse {t}/sparse/a.png --out {t}/rgb", 1, "input"),
    ("predict --method classical --rgb {t}/missing --sparse {t}/sparse --out {t}/new", 2, "--rgb"),
    ("predict --rgb {t}/rgb --sparse {t}/sparse --out {t}/new", 2, "--checkpoint"),
    ("predict --method classical --out {t}/new", 2, "--rgb"),
    ("predict --method classical --rgb {t}/rgb --sparse {t}/sparse --out {t}/new --ply", 2, "--kitti-raw"),
    ("predict --method classical --rgb {t}/rgb --sparse {t}/sparse --out {t}/new --amp fp8", 2, "--amp"),
    # visualize
    ("visualize --pred {t}/pred --out {t}/pred", 1, "input folder"),
    ("visualize --pred {t}/pred --out {t}/out --gt {t}/gt", 1, "exists"),
    ("visualize --pred {t}/pred --out {t}/new --vmax 0", 2, "--vmax"),
    ("visualize --pred {t}/pred --out {t}/new --vmax inf", 2, "--vmax"),
    ("visualize --pred {t}/bad/corrupt.png --out {t}/new", 1, "corrupt.png"),
    ("visualize --pred {t}/pred --out {t}/afile/x", 1, "afile"),
    ("visualize --pred {t}/pred --out {t}/ro/x", 1, "ro"),
    ("visualize --pred {t}/rgb --out {t}/new", 1, "16-bit"),
    # metrics
    ("metrics {t}/pred {t}/gt --json {t}/existing.json", 1, "existing.json exists"),
    ("metrics {t}/pred {t}/gt --json {t}/pred/a.png --overwrite", 1, "a.png"),
    ("metrics {t}/pred {t}/gt --json {t}/afile/m.json", 1, "afile"),
    ("metrics {t}/pred {t}/gt --json {t}/ro/m.json", 1, "ro"),
    ("metrics {t}/pred {t}/gt --min-gt nan", 2, "--min-gt"),
    ("metrics {t}/pred {t}/gt --min-gt -1", 2, "--min-gt"),
    ("metrics {t}/pred {t}/rgb", 1, "16-bit"),
    ("metrics {t}/pred {t}/sem", 1, "16-bit"),
    ("metrics {t}/missing {t}/gt", 2, "'PRED'"),
    # evaluate
    ("evaluate --data {t}/rgb --method classical --out {t}/new", 1, "no val_select frames found"),
    ("evaluate --data {t}/missing", 2, "--data"),
    ("evaluate --data {t}/rgb --batch-size 0", 2, "--batch-size"),
    ("evaluate --data {t}/rgb --workers -1", 2, "--workers"),
    ("evaluate --data {t}/rgb --pictures -2", 2, "--pictures"),
    ("evaluate --data {t}/rgb --max-frames 0", 2, "--max-frames"),
    ("evaluate --data {t}/rgb --save-predictions", 2, "--out"),
    # submit
    ("submit --checkpoint {t}/afile --data {t}/rgb --out {t}/new --expected-frames -1", 2, "--expected-frames"),
    ("submit --checkpoint {t}/missing.pt --data {t}/rgb --out {t}/new", 2, "--checkpoint"),
    ("submit --checkpoint {t}/afile --data {t}/rgb --out {t}/rgb/sub", 1, "input folder"),
    # train
    ("train --data {t}/rgb --out {t}/run --lr nan", 2, "--lr"),
    ("train --data {t}/rgb --out {t}/run --lr -0.1", 2, "--lr"),
    ("train --data {t}/rgb --out {t}/run --epochs 0", 2, "--epochs"),
    ("train --data {t}/rgb --out {t}/run --batch-size -4", 2, "--batch-size"),
    ("train --data {t}/rgb --out {t}/run --max-steps -1", 2, "--max-steps"),
    ("train --data {t}/rgb --out {t}/run --crop 0x128", 2, "--crop"),
    ("train --data {t}/rgb --out {t}/run --crop 64xabc", 2, "--crop"),
    ("train --data {t}/rgb --out {t}/run --width inf", 2, "--width"),
    ("train --data {t}/rgb --out {t}/run --set lr=nan", 1, "lr"),
    ("train --data {t}/rgb --out {t}/run --set epochs=-3", 1, "epochs"),
    ("train --data {t}/rgb --out {t}/run --set nosuch=1", 1, "nosuch"),
    ("train --resume", 2, "--out"),
    ("train --resume --out {t}/out", 1, "last.pt"),
    # synth
    ("synth --out {t}/new --frames 0", 2, "--frames"),
    ("synth --out {t}/new --frames -5", 2, "--frames"),
    ("synth --out {t}/new --size 0x10", 2, "--size"),
    ("synth --out {t}/new --size 10", 2, "--size"),
    ("synth --out {t}/new --workers 0", 2, "--workers"),
    ("synth --out {t}/new --eval-frames 1", 2, "--eval-frames"),
    # data check
    ("data check {t}/missing", 2, "ROOTS"),
    ("data check {t}/rgb --sample 0", 2, "--sample"),
    # segment
    ("segment --model unknown --images {t}/rgb --out {t}/new --batch-size 0", 2, "--batch-size"),
    ("segment --model unknown --images {t}/rgb --out {t}/new --input-size 0x0", 2, "--input-size"),
    ("segment --model unknown --images {t}/missing --out {t}/new", 2, "--images"),
    # project
    ("project --velodyne {t}/afile --out {t}/new.png --scan-period 0 --K 1,1,1,1 --T 1 --size 4x4", 2, "--scan-period"),
    ("project --velodyne {t}/missing.bin --out {t}/new.png", 2, "missing.bin"),
    # demo / ablate / bench
    ("demo --out {t}/new --minutes nan", 2, "--minutes"),
    ("demo --out {t}/new --frames 0", 2, "--frames"),
    ("demo --out {t}/new --size 0x320", 2, "--size"),
    ("demo --out {t}/new --width -1", 2, "--width"),
    ("ablate --out {t}/new --backbone-steps 0", 2, "--backbone-steps"),
    ("ablate --out {t}/new --eval-frames -1", 2, "--eval-frames"),
    ("bench --repeats 0", 2, "--repeats"),
    ("bench --size 0x0", 2, "--size"),
    ("bench --width nan", 2, "--width"),
    ("bench --json {t}/existing.json --parts propagation --size 32x32", 1, "existing.json exists"),
    # info / convert
    ("info {t}/afile", 1, "afile"),
    ("info {t}/missing.pt", 2, "missing.pt"),
    ("convert {t}/afile {t}/new.pt", 1, "afile"),
]


@pytest.fixture(scope="module")
def user_tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("user")
    _tree(root)
    yield root
    os.chmod(root / "ro", stat.S_IRWXU)


@pytest.mark.parametrize(
    ("args", "code", "fragment"), CASES, ids=[c[0].split(" {t}")[0] + f"-{i}" for i, c in enumerate(CASES)]
)
def test_bad_input_is_a_one_line_error_and_changes_nothing(
    user_tree: Path, args: str, code: int, fragment: str
) -> None:
    if fragment == "ro" and os.geteuid() == 0:
        pytest.skip("root ignores folder permissions")
    before = _hashes(user_tree)
    result = CliRunner().invoke(main, args.format(t=user_tree).split(), catch_exceptions=True)
    output = result.output + (result.stderr if result.stderr_bytes is not None else "")
    assert "Traceback" not in output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code == code, output
    assert fragment.lower() in output.lower(), output
    assert _hashes(user_tree) == before
    assert not (user_tree / "new").exists() or not any((user_tree / "new").iterdir())


def test_count() -> None:
    assert len(CASES) >= 60
