"""``adapt --overwrite`` destroys nothing before the replacement is ready: the inputs are checked (readable frames,
frames not smaller than the crop, readable weights, none inside OUT) and the run trains with the earlier run's files
left whole; they go only once the new run's first state is complete, and a SIGKILL at any step leaves OUT holding
one run or the other, never a mix."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from semattnet._errors import DataError, InputError
from semattnet._utils.outputs import OutputError
from semattnet._utils.run_folder import READY, REPLACE_PREFIX, finish_replacements
from semattnet.data.frames import Frame
from semattnet.training.adapt import FINAL, LOG, RUN_FILES, STATE, Adapter, adapt
from semattnet.training.adapt.run import run_files
from semattnet.weights.checkpoint import CheckpointError, load_checkpoint
from tests.training._adapt_runs import digests, rt_checkpoint
from tests.training.test_adapt import _cfg, _Frames, _quiet

pytestmark = pytest.mark.filterwarnings("ignore:no semantic maps given")

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rt_weights(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rt_checkpoint(tmp_path_factory.mktemp("rt-weights") / "rt.safetensors")


@pytest.fixture
def earlier(rt_weights: Path, tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A finished run in ``tmp_path/run`` (seed 0) and the digests of its files."""
    out = tmp_path / "run"
    adapt(_cfg(rt_weights, out, save_every=1), _Frames(), log=_quiet)
    before = digests(out)
    assert set(before) == set(RUN_FILES)
    return out, before


class _Small(_Frames):
    """Frames of 16x16 pixels: smaller than any crop the network takes."""

    def load(self, name: str) -> Frame:
        frame = super().load(name)
        assert frame.gt is not None
        return Frame(name, frame.rgb[:16, :16], frame.sparse[:16, :16], gt=frame.gt[:16, :16])


class _Inside(_Frames):
    """Frames whose source reads ``path`` (a file inside the run folder)."""

    def __init__(self, path: Path) -> None:
        super().__init__()
        self.path = path

    def inputs(self) -> list[Path]:
        return [self.path]


def test_an_overwrite_whose_frames_cannot_be_read_keeps_the_earlier_run(
    earlier: tuple[Path, dict[str, str]], rt_weights: Path
) -> None:
    out, before = earlier
    with pytest.raises(DataError, match="none of its 2 frame"):
        adapt(_cfg(rt_weights, out), _Frames(2, bad=("f0", "f1")), overwrite=True, log=_quiet)
    assert digests(out) == before


def test_an_overwrite_whose_frames_are_smaller_than_the_crop_keeps_the_earlier_run(
    earlier: tuple[Path, dict[str, str]], rt_weights: Path
) -> None:
    out, before = earlier
    with pytest.raises(InputError, match="smaller than 32"):
        adapt(_cfg(rt_weights, out), _Small(), overwrite=True, log=_quiet)
    assert digests(out) == before


def test_an_overwrite_from_truncated_weights_keeps_the_earlier_run(
    earlier: tuple[Path, dict[str, str]], rt_weights: Path, tmp_path: Path
) -> None:
    out, before = earlier
    cut = tmp_path / "cut.safetensors"
    cut.write_bytes(rt_weights.read_bytes()[: rt_weights.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="cut.safetensors"):
        adapt(_cfg(cut, out), _Frames(), overwrite=True, log=_quiet)
    assert digests(out) == before


@pytest.mark.parametrize("overwrite", [True, False])
def test_weights_inside_the_run_folder_are_refused_in_one_line_and_nothing_deleted(
    earlier: tuple[Path, dict[str, str]], overwrite: bool
) -> None:
    out, before = earlier
    with pytest.raises(InputError) as info:
        adapt(_cfg(out / FINAL, out), _Frames(), overwrite=overwrite, log=_quiet)
    assert str(out / FINAL) in str(info.value) and "\n" not in str(info.value)
    assert digests(out) == before


def test_any_input_file_inside_the_run_folder_is_refused_and_nothing_deleted(
    earlier: tuple[Path, dict[str, str]], rt_weights: Path
) -> None:
    out, before = earlier
    frames = out / "frames" / "list.txt"
    frames.parent.mkdir()
    frames.write_text("f0\n")
    with pytest.raises(InputError, match=f"{frames}: an input of this run lies inside its run folder"):
        adapt(_cfg(rt_weights, out), _Inside(frames), overwrite=True, log=_quiet)
    assert digests(out) == before and frames.read_text() == "f0\n"


def test_an_overwrite_that_fails_before_its_first_state_keeps_the_earlier_run(
    earlier: tuple[Path, dict[str, str]], rt_weights: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out, before = earlier
    step = Adapter._step

    def second_step_fails(self: Adapter) -> dict[str, float]:
        if self.step == 1:
            raise RuntimeError("out of memory at step 2")
        return step(self)

    monkeypatch.setattr(Adapter, "_step", second_step_fails)
    with pytest.raises(RuntimeError, match="step 2"):
        adapt(_cfg(rt_weights, out, save_every=2, seed=1), _Frames(), overwrite=True, log=_quiet)
    assert digests(out) == before
    assert not list(out.glob(f"{REPLACE_PREFIX}*"))


def test_a_finished_overwrite_replaces_the_run_files_only(
    earlier: tuple[Path, dict[str, str]], rt_weights: Path
) -> None:
    out, before = earlier
    (out / "notes.txt").write_text("mine")
    adapt(_cfg(rt_weights, out, seed=1), _Frames(), overwrite=True, log=_quiet)
    after = digests(out)
    assert set(after) == set(RUN_FILES) and all(after[f] != before[f] for f in RUN_FILES)
    assert json.loads((out / LOG).read_text())["config"]["seed"] == 1
    assert {p.name for p in out.iterdir()} == {"notes.txt", FINAL, LOG, "checkpoints"}  # no stage, no lock


#: Run in a subprocess: imports once, then forks one process per kill point, each overwriting its own copy of the
#: earlier run and SIGKILLing itself just before its Nth change of the file system (a rename, a removal).
_KILLER = """
import json, os, shutil, signal, sys, traceback, warnings
from pathlib import Path
sys.path.insert(0, sys.argv[1])
warnings.simplefilter("ignore")
from tests.training.test_adapt import _cfg, _Frames, _quiet
from semattnet.training.adapt import adapt
import torch, torch._dynamo, semattnet.weights.hub  # what a run imports on its way: once, before the forks
torch.optim.Adam([torch.zeros(1, requires_grad=True)], fused=True)
weights, template, work = Path(sys.argv[2]), Path(sys.argv[3]), Path(sys.argv[4])

def overwrite(out, kill_at, trace):
    count = 0
    def counted(name, fn):
        def call(*args, **kwargs):
            nonlocal count
            count += 1
            with open(trace, "a") as f:
                f.write(json.dumps([name, *map(str, args)]) + "\\n")
            if count == kill_at:
                os.kill(os.getpid(), signal.SIGKILL)
            return fn(*args, **kwargs)
        return call
    for name in ("replace", "rename", "unlink", "rmdir"):
        setattr(os, name, counted(name, getattr(os, name)))
    adapt(_cfg(weights, out, save_every=1, seed=1), _Frames(), overwrite=True, log=_quiet)

def fork(k):
    out, trace = work / f"run{k}", work / f"trace{k}.jsonl"
    shutil.copytree(template, out)
    pid = os.fork()
    if pid == 0:
        code = 0
        try:
            overwrite(out, k, trace)
        except BaseException:
            traceback.print_exc()
            code = 1
        os._exit(code)
    return os.waitpid(pid, 0)[1]

statuses = {0: fork(0)}
steps = len((work / "trace0.jsonl").read_text().splitlines())
for k in range(1, steps + 1):
    statuses[k] = fork(k)
print(json.dumps(statuses))
"""


def _ops(trace: Path) -> list[list[str]]:
    """The changes a run made, as ``[call, path...]`` with the names that vary from run to run (the copy's folder,
    process ids, temporary names) masked."""
    lines = trace.read_text().splitlines() if trace.exists() else []
    return [
        [re.sub(r"run\d+", "run", re.sub(r"\d+\.[a-z0-9_]{8}", "N", a)) for a in json.loads(line)] for line in lines
    ]


def _one_run(out: Path, before: dict[str, str], committed: bool) -> None:
    """After the next run's recovery, ``out`` holds the earlier run untouched or the new run's state, whole."""
    finish_replacements(out, run_files)
    assert not list(out.glob(f"{REPLACE_PREFIX}*"))
    if not committed:
        assert digests(out) == before
        return
    state = load_checkpoint(out / STATE).extra
    log = json.loads((out / LOG).read_text())
    assert state["adapt_config"]["seed"] == 1 and log["config"]["seed"] == 1
    steps = [r["step"] for r in log["steps"]]  # the log is written first: it may hold one step more
    assert steps[: state["step"]] == list(range(1, state["step"] + 1)) and len(steps) <= state["step"] + 1
    assert not (out / FINAL).exists() or digests(out)[FINAL] != before[FINAL]


# ~19 s: a SIGKILL at each of ~14 points; the default suite runs the overwrite, the unreadable frames, the refusals
@pytest.mark.slow
def test_sigkill_at_each_step_of_an_overwrite_leaves_the_earlier_run_whole_until_the_new_one_is(
    earlier: tuple[Path, dict[str, str]], rt_weights: Path, tmp_path: Path
) -> None:
    template, before = earlier
    work = tmp_path / "kills"
    work.mkdir()
    env = os.environ | {"OMP_NUM_THREADS": "1"}
    args = [sys.executable, "-c", _KILLER, str(REPO), str(rt_weights), str(template), str(work)]
    res = subprocess.run(args, capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    statuses = {int(k): v for k, v in json.loads(res.stdout.splitlines()[-1]).items()}
    assert statuses[0] == 0, res.stderr[-3000:]
    whole = _ops(work / "trace0.jsonl")
    commit = next(i for i, op in enumerate(whole, 1) if op[0] == "replace" and op[-1].endswith(f"/{READY}"))
    assert 1 < commit < len(whole) and len(statuses) == len(whole) + 1
    for k in range(1, len(whole) + 1):
        assert os.WIFSIGNALED(statuses[k]) and os.WTERMSIG(statuses[k]) == 9, (k, whole[k - 1])
        assert _ops(work / f"trace{k}.jsonl") == whole[:k]  # killed just before step k, as the whole run took it
        out = work / f"run{k}"
        if k <= commit:  # the new state not yet committed: the earlier run as it was, byte for byte
            assert digests(out) == before, (k, whole[k - 1])
        _one_run(out, before, committed=k > commit)
    resumed = work / f"run{commit + 1}"  # killed just after the commit: the new run continues from its first state
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as the killed runs computed (OMP_NUM_THREADS=1): the same sums in the same order
    try:
        adapt(_cfg(rt_weights, resumed), _Frames(), resume=True, log=_quiet)
    finally:
        torch.set_num_threads(threads)
    a, b = (load_checkpoint(run / FINAL).state_dict for run in (work / "run0", resumed))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_a_stage_left_by_a_killed_overwrite_is_cleared_and_a_damaged_mark_refused(tmp_path: Path) -> None:
    out = tmp_path / "run"
    (out / "checkpoints").mkdir(parents=True)
    (out / "log.json").write_text("{}")
    dead = out / f"{REPLACE_PREFIX}999999999.abcdefgh"
    dead.mkdir()
    (dead / "log.json").write_text("new")
    finish_replacements(out, run_files)
    assert not dead.exists() and (out / "log.json").read_text() == "{}"  # not committed: the earlier run stays
    dead.mkdir()
    (dead / READY).write_text(json.dumps({"move": ["../../outside"]}))
    with pytest.raises(OutputError, match=f"{READY}: damaged mark") as info:
        finish_replacements(out, run_files)
    assert "\n" not in str(info.value) and (out / "log.json").read_text() == "{}" and dead.is_dir()
