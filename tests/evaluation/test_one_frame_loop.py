"""One frame loop (issues 34, 55): every module of ``semattnet.evaluation`` that completes frames does it through
:func:`~semattnet.inference.pipeline.complete_frames` (or ``plan.run``, a
:class:`~semattnet.inference.pipeline.RunPlan`'s run: the same loop), and no module of any subpackage (the live
node's included) has a loop of its own but the loop's own modules and those listed with why they may
(:data:`WHY_IT_MAY`), read from the source with ``ast``.

A private loop shows in one of four ways: a completer, engine or model called on inputs (``completer(rgb,
...)``, ``engine.run(...)``), the loop's own parts used (``completions``, ``read_frame``, ``predict_frame``,
``write_prediction``), frames walked by index (``range(len(ds))``), or frames loaded one by one inside a loop
(``ds.load(i)`` in a ``for``, ``while`` or comprehension). A zero-argument call (``completer()``: a factory) and
one ``source.load`` outside a loop (to read a size) are not loops.
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import pytest

import semattnet

EVALUATION = Path(semattnet.__file__).resolve().parent / "evaluation"
#: Names of what completes frames: a call of one of them on arguments runs frames outside the loop.
COMPLETERS = ("completer", "engine", "model", "net")
#: Calls of an engine or completer method on inputs.
ENGINE_METHODS = ("run", "complete", "infer", "forward")
#: The frame loop's own parts: using them is a second loop.
LOOP_PARTS = ("completions", "read_frame", "predict_frame", "write_prediction")
LOOPS = (ast.For, ast.AsyncFor, ast.While, ast.ListComp, ast.SetComp, ast.DictComp, ast.GeneratorExp)


def _name(func: ast.expr) -> str:
    return func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""


def _runs_the_loop(node: ast.Call) -> bool:
    """``complete_frames(...)`` or ``plan.run(...)``: the one loop."""
    func = node.func
    plan_run = isinstance(func, ast.Attribute) and func.attr == "run" and _name(func.value) == "plan"
    return _name(func) == "complete_frames" or plan_run


def _is_range_len(node: ast.Call) -> bool:
    """``range(...)`` over a length: ``range(len(ds))``, ``range(min(len(ds), n))``."""
    return _name(node.func) == "range" and any(
        isinstance(a, ast.Call) and _name(a.func) == "len" for arg in node.args for a in ast.walk(arg)
    )


def private_loops(source: str) -> list[str]:
    """``line: what`` for each sign of a frame loop of its own in ``source`` (a module's text)."""
    tree, found = ast.parse(source), []
    in_loop = {id(n) for loop in ast.walk(tree) if isinstance(loop, LOOPS) for n in ast.walk(loop) if n is not loop}
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call) or _runs_the_loop(node):
            continue
        name, argued = _name(node.func), bool(node.args or node.keywords)
        if argued and name in COMPLETERS:
            found.append(f"{node.lineno}: calls {name}(...) on inputs")
        elif argued and isinstance(node.func, ast.Attribute) and name in ENGINE_METHODS:
            found.append(f"{node.lineno}: calls .{name}(...) on inputs")
        elif name in LOOP_PARTS:
            found.append(f"{node.lineno}: uses the loop's part {name}")
        elif _is_range_len(node):
            found.append(f"{node.lineno}: walks frames by index (range(len(...)))")
        elif name == "load" and isinstance(node.func, ast.Attribute) and id(node) in in_loop:
            found.append(f"{node.lineno}: loads frames one by one in a loop")
    return sorted(found, key=lambda line: int(line.split(":")[0]))


#: The sweep's and the submission's own loops before they ran through complete_frames (abridged).
OLD_LOOPS = textwrap.dedent("""
    def _score_setting(ds, setting, completers, seed, max_frames):
        for i in range(min(len(ds), max_frames or len(ds))):
            s = ds.load(i)
            sparse = thin(s.sparse, setting, seed=seed + i)
            for name, completer in completers.items():
                depth = completer(s.rgb, sparse, None).depth

    def predictions(ds, completer):
        for i in progress_bar(range(len(ds)), desc="test split"):
            x = ds[i]
            yield completer.run(x["rgb"][None], x["semantic"][None], x["sparse"][None])

    def by_parts(source, model):
        return [c for _, c in completions(source, model)]

    def loaded(source, names):
        return [source.load(n) for n in names]
""")

#: What the scoring modules do instead: one loop, a factory called without arguments, one size read.
THROUGH_THE_LOOP = textwrap.dedent("""
    def evaluate(source, completer, sinks, stage):
        model = completer() if callable(completer) else completer
        size = source.load(source.names[0]).size
        for k, (name, method) in enumerate(methods.items()):
            complete_frames(source, method, sinks, stage / f"run{k}")
        plan = check_frames(source, sinks, stage)
        plan.run(completer, log=print)
        return size
""")


def test_the_check_finds_each_kind_of_private_loop() -> None:
    found = private_loops(OLD_LOOPS)
    assert found == [
        "3: walks frames by index (range(len(...)))",
        "4: loads frames one by one in a loop",
        "7: calls completer(...) on inputs",
        "10: walks frames by index (range(len(...)))",
        "12: calls .run(...) on inputs",
        "15: uses the loop's part completions",
        "18: loads frames one by one in a loop",
    ]
    assert private_loops(THROUGH_THE_LOOP) == []


@pytest.mark.parametrize("path", sorted(EVALUATION.glob("*.py")), ids=lambda p: p.name)
def test_no_evaluation_module_loops_over_frames(path: Path) -> None:
    assert private_loops(path.read_text(encoding="utf-8")) == [], f"{path}: complete frames through complete_frames"


@pytest.mark.parametrize("module", ["evaluate.py", "sparsity.py", "submission.py"])
def test_the_scoring_modules_run_the_one_loop(module: str) -> None:
    """What completes frames in ``evaluation`` calls ``complete_frames`` or ``plan.run`` (and so is not a module
    without frames)."""
    tree = ast.parse((EVALUATION / module).read_text(encoding="utf-8"))
    assert any(isinstance(n, ast.Call) and _runs_the_loop(n) for n in ast.walk(tree)), module


SRC = EVALUATION.parent
#: The modules that show a sign of a frame loop and why that is not a second one (module -> why).
WHY_IT_MAY = {
    "_startup.py": "reads the process's command-line words by index, no frames",
    "models/anchor.py": "the classical completion calls its C++ kernel's complete() on one batch of sparse maps",
    "models/anchor_kernel.py": "the C++ kernel's complete() on one batch of sparse maps, no frames",
    "inference/feed.py": "the loop's reader and completion: the one loop",
    "inference/loop.py": "the loop itself",
    "inference/live.py": "the loop for frames a sensor pushes: feed's live reader, the sinks' lifecycle",
    "inference/pipeline.py": "complete_frames: plan.run, the loop",
    "inference/sinks/base.py": "write_prediction, the loop's one writer",
    "inference/completer.py": "DepthCompleter: the engine call on one frame or a batch, and stream() = completions",
    "inference/backends/onnxruntime_engine.py": "an engine: runs the network on one padded batch",
    "inference/backends/openvino_engine.py": "an engine: runs the network on one padded batch",
    "inference/backends/torch_engine.py": "an engine: runs the network on one padded batch",
    "inference/backends/calibration.py": "int8's calibration frames read once to quantise (no completion)",
    "models/generalist.py": "the generalist's forward calls its network",
    "baselines/prior.py": "the monocular prior's network on the one image a completer call is given",
    "models/macs.py": "counts a forward's multiply-accumulates",
    "models/rt.py": "layers indexed in a forward",
    "models/bn_folding.py": "modules indexed while folding",
    "weights/export.py": "traces a forward to export it",
    "segmentation/hf.py": "a segmenter's forward",
    "segmentation/segmenter.py": "a segmenter's forward",
    "segmentation/datasets.py": "a split's maps segmented once into a cache (no depth completion)",
    "data/frames.py": "IndexedSource.load over its own items (the source side)",
    "data/datasets/check.py": "decodes every frame of a split to check it (no completion)",
    "training/trainer.py": "training batches (a DataLoader), not frames to complete",
    "training/validation.py": "validation batches of the training loop",
    "training/reference.py": "the authors' training step, for the benchmark",
    "training/generalist.py": "the generalist's training batches and calibration",
    "training/adapt/model.py": "adapt's forward on training crops",
    "training/adapt/pool.py": "adapt's frame pool read once through read_frame (no completion)",
    "training/adapt/run.py": "adapt's training steps and its held-out metric on a few frames",
    "apps/experiment.py": "the demo's held-out scenes, completed in batches by a trained network",
    "apps/benchmark.py": "times a forward",
    "apps/front_figure.py": "the README figure's few scenes",
    "cli/weights.py": "lists registry rows by index",
    "robotics/bag_source.py": "numbers the bag's pairs (no completion)",
}


def _modules() -> list[str]:
    return sorted(str(p.relative_to(SRC)) for p in SRC.rglob("*.py"))


@pytest.mark.parametrize("module", [m for m in _modules() if m not in WHY_IT_MAY])
def test_no_module_of_any_subpackage_has_a_frame_loop_of_its_own(module: str) -> None:
    found = private_loops((SRC / module).read_text(encoding="utf-8"))
    assert found == [], f"{module}: complete frames through the one loop (or say in WHY_IT_MAY why it may): {found}"


def test_every_listed_module_exists_and_still_needs_its_reason() -> None:
    stale = [m for m in WHY_IT_MAY if not (SRC / m).is_file() or not private_loops((SRC / m).read_text())]
    assert stale == [], f"no longer a sign of a loop (drop from WHY_IT_MAY): {stale}"
