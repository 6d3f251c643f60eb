"""Prediction and pictures for a user's frames: ``predict``, ``visualize``.

``predict``'s options are declared by their owners: each kind of input in :mod:`semattnet.cli._inputs`'s
table, the outputs and run options in :mod:`semattnet.cli._outputs`, the model's in :mod:`semattnet.cli._model`;
its ``--help`` lists them under those headings.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import click

from semattnet.cli._group import main
from semattnet.cli._inputs import MAP_OPTIONS, ChosenInput, choose_input, input_params
from semattnet.cli._model import ModelOptions, model_options
from semattnet.cli._options import DEPTH_M, weights_input
from semattnet.cli._outputs import AskedSinks, Outputs, RunCommandOptions, output_options, sink_params
from semattnet.cli._params import GeneratedCommand, values_of, with_options

if TYPE_CHECKING:
    from semattnet.inference.pipeline import FrameRun

#: The options that do not change what a run writes: a resumed run may differ from the first in these only (and in
#: the registries' options declared so: ``option(..., identity=False)``).
_NOT_IDENTITY = {"resume", "overwrite", "on_error", "stream", "realtime", "speed", "out"}


def _not_identity() -> set[str]:
    """:data:`_NOT_IDENTITY` and the sources' and sinks' options declared so."""
    from semattnet._utils.registry import volatile
    from semattnet.data.sources.registry import SOURCES
    from semattnet.inference.sinks import SINKS

    options = [e.options for e in SOURCES.values()] + [e.options for e in SINKS.values()]
    return _NOT_IDENTITY.union(*(volatile(o) for o in options if o is not None))


def _identity(params: Mapping[str, object]) -> dict[str, object]:
    """What a run is, for a resume to check: every option that changes the outputs (paths resolved, a
    weights file or folder by its SHA-256) and the package version."""
    from semattnet._utils.version import __version__
    from semattnet.cache import sha256_file, sha256_tree

    run: dict[str, object] = {"command": "predict", "version": __version__}
    skip = _not_identity()
    for key, value in sorted(params.items()):
        if key in skip or value is None or value is False:
            continue
        if key == "weights" and Path(str(value)).is_file():  # a file by its digest (--checkpoint arrives here too)
            value = f"sha256:{sha256_file(str(value))}"
        elif key == "weights" and Path(str(value)).is_dir():  # a folder (hf layout) by every file in it
            value = f"sha256-tree:{sha256_tree(str(value))}"
        run[key] = str(Path(value).resolve()) if isinstance(value, Path) else value
    return run


@main.command(cls=GeneratedCommand, generated=[("", input_params), ("report", sink_params)])
@with_options(MAP_OPTIONS)
@model_options()
@output_options
def predict(**params: object) -> None:
    """Complete depth for one frame, folders of frames (any size), a KITTI split or raw drive, a dataset
    or a ROS bag.

    A frame that cannot be completed is skipped with one line (--on-error); OUT/frames.json records every
    frame. Exit status: 0 when every frame was done, 3 when some were skipped, 4 when --realtime dropped
    some (and none was skipped). Prints a per-stage latency table at the end and writes OUT/latency.json."""
    import os

    from semattnet._utils.distributed import launch_rank

    ctx = click.get_current_context()
    chosen = choose_input(ctx)
    listing = chosen.values.listing()
    if listing is not None:
        click.echo(listing)
        return
    outputs, run, model = (
        values_of(Outputs, params),
        values_of(RunCommandOptions, params),
        values_of(ModelOptions, params),
    )
    asked = AskedSinks.of(params)
    out, resuming = outputs.check(chosen, asked)
    run.check(chosen)
    model.check()
    result = _run_frames(chosen, (outputs, asked), run, model, (out, resuming), _identity(params))
    if launch_rank() == 0:
        click.echo(result.summary())
    launched = int(os.environ.get("WORLD_SIZE", "1")) > 1  # torchrun takes any other status for a crash
    if result.exit_code and not launched:
        ctx.exit(result.exit_code)


def _run_frames(
    chosen: ChosenInput,
    outputs_asked: tuple[Outputs, AskedSinks],
    run: RunCommandOptions,
    model: ModelOptions,
    folder: tuple[Path, bool],
    identity: dict[str, object],
) -> FrameRun:
    """Check everything, load the completer, run the one frame loop; then the table (and the report).
    ``outputs_asked``: the shared output options and the sinks' own; ``folder``: the output folder and whether to
    resume; ``identity``: the run's, for a resume to check."""
    from semattnet._utils.distributed import launch_rank, process_group
    from semattnet.data.sources import FolderSource
    from semattnet.inference.pipeline import check_frames
    from semattnet.inference.timing import StageTimes

    out, resuming = folder
    outputs, asked = outputs_asked
    timer = StageTimes()
    sinks = outputs.sinks(asked, timer)
    with process_group():
        source, maps = chosen.open(model.device)
        spec = outputs.spec(resuming, identity, [weights_input(model.weights)[1]])
        plan = check_frames(source, sinks, out, spec, run.options())  # before the model
        try:
            if plan.journal.kept:
                click.echo(f"{out}: resuming: {len(plan.journal.kept)} of {len(source.names)} frame(s) already done")
            result = plan.run(model.completer(), semantic=maps, timer=timer, log=click.echo)
        finally:
            plan.release()  # also when the model cannot be loaded
    if launch_rank() == 0:
        click.echo(timer.table())
        if maps.note:
            click.echo(f"semantic maps: {maps.note}")
    if outputs.report and launch_rank() == 0 and isinstance(source, FolderSource):  # once, after every rank's frames
        from semattnet.viz.viewer import write_prediction_report

        done = [source.frames[p.stem] for p in result.paths]
        write_prediction_report(out, done, K=source.K, log=click.echo)
    return result


@main.command()
@click.option("--pred", required=True, type=click.Path(exists=True, path_type=Path), help="16-bit PNG file or folder.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option("--gt", type=click.Path(exists=True, path_type=Path), default=None, help="Ground truth: adds error maps.")
@click.option("--vmax", type=DEPTH_M, default=80.0, show_default=True, help="Depth of the colour scale's top, metres.")
@click.option("--overwrite", is_flag=True, help="Replace existing pictures.")
def visualize(pred: Path, out: Path, gt: Path | None, vmax: float, overwrite: bool) -> None:
    """Colourise saved depth predictions (and error maps against ground truth)."""
    from semattnet.viz.depth import write_depth_pictures

    count = write_depth_pictures(pred, out, gt, vmax, overwrite=overwrite)
    click.echo(f"wrote {count} picture(s) to {out}")
