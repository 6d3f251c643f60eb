"""``predict``'s options, declared by their owners: the grouped ``--help``, the one ownership rule over the table
of input kinds (:data:`semattnet.cli._inputs.INPUTS`), and the registries' options all on the command."""

from __future__ import annotations

import re
from dataclasses import dataclass, fields
from pathlib import Path
from typing import ClassVar

import click
import pytest
from click.testing import CliRunner

from semattnet._utils.registry import option as cli_option
from semattnet.cli import main
from semattnet.cli._inputs import INPUTS, MAP_OPTIONS, InputKind, choose_input, input_options, or_list
from semattnet.cli._params import OTHER, SectionedCommand, heading_of
from semattnet.cli.predict import predict
from semattnet.data.sources.registry import SourceOptions

HEADINGS = [
    "Inputs: files",
    "Inputs: KITTI raw drive",
    "Inputs: dataset",
    "Inputs: ROS bag",
    "Semantic maps",
    "Model",
    "Outputs",
    "Run",
    OTHER,
]


def _help() -> str:
    result = CliRunner().invoke(main, ["predict", "--help"], terminal_width=120)
    assert result.exit_code == 0, result.output
    return result.output


def _sections(text: str) -> dict[str, str]:
    """Heading -> the lines under it (a heading: an unindented line ending in ':')."""
    parts = re.split(r"^(\S[^\n]*):\n", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2], strict=True))


def test_help_lists_the_options_under_their_headings_in_order() -> None:
    sections = _sections(_help())
    assert [h for h in sections if h != "Usage"] == HEADINGS


def test_every_option_is_under_exactly_one_heading() -> None:
    sections = _sections(_help())
    ctx = click.Context(predict)
    for param in predict.get_params(ctx):
        record = param.get_help_record(ctx)
        assert record is not None, param.name
        under = [h for h, body in sections.items() if re.search(rf"^ +{re.escape(record[0])}( |$)", body, re.M)]
        assert under == [heading_of(param)], (param.name, under)


def _value(option: click.Option, tmp_path: Path) -> list[str]:
    """A value the option accepts (so only the ownership rule can refuse it)."""
    if option.is_flag:
        return []
    if isinstance(option.type, click.Choice):
        return [str(option.type.choices[-1])]
    if isinstance(option.type, click.Path):
        return [str(tmp_path / ("folder" if option.type.dir_okay else "file.json"))]
    return ["0.5"]


def _choose(kind: InputKind, tmp_path: Path) -> list[str]:
    """The options choosing ``kind``, with values that exist."""
    return [
        a for name in kind.selects for o in kind.options if o.name == name for a in (o.opts[0], *_value(o, tmp_path))
    ]


def _misplaced() -> list[tuple[str, str, str]]:
    """(option name, the kind it is given with, the kinds' flags named in the error) for every option an input kind
    owns (but does not choose it by) or takes, given with a kind that does not take it."""
    taken = [
        *(o for k in INPUTS for o in k.options if o.name not in k.selects),  # (selecting: the one-input rule)
        *(o for o in MAP_OPTIONS if any(k.takes(str(o.name)) for k in INPUTS)),
    ]
    cases = []
    for option in taken:
        owners = [k.flag for k in INPUTS if k.takes(str(option.name))]
        for kind in INPUTS:
            if not kind.takes(str(option.name)):
                cases.append((str(option.name), kind.name, or_list(owners)))
    return cases


@pytest.mark.parametrize(("name", "with_kind", "owners"), _misplaced())
def test_an_option_of_another_input_kind_is_one_usage_error(
    tmp_path: Path, name: str, with_kind: str, owners: str
) -> None:
    (tmp_path / "folder").mkdir()
    (tmp_path / "file.json").write_text("{}")
    kind = next(k for k in INPUTS if k.name == with_kind)
    option = next(o for o in predict.params if o.name == name)
    assert isinstance(option, click.Option)
    args = [*_choose(kind, tmp_path), option.opts[0], *_value(option, tmp_path), "--out", str(tmp_path / "o")]
    result = CliRunner().invoke(main, ["predict", "--method", "classical", *args])
    assert result.exit_code == 2, result.output
    said = result.output.strip().splitlines()[-1]
    assert f"{option.opts[0]} is an option of {owners}" in said and said.endswith(f", not of {kind.flag}"), said
    assert not (tmp_path / "o").exists()


def test_exactly_one_input_kind() -> None:
    wanted = "give --rgb and --sparse, or --kitti-raw, or --data (with --dataset), or --bag"
    result = CliRunner().invoke(main, ["predict", "--method", "classical", "--out", "o"])
    assert result.exit_code == 2 and wanted in result.output, result.output
    result = CliRunner().invoke(main, ["predict", "--rgb", ".", "--sparse", ".", "--bag", ".", "--out", "o"])
    assert result.exit_code == 2 and "(one of them: not --rgb and --bag)" in result.output, result.output


@pytest.mark.parametrize("kind", INPUTS, ids=lambda k: k.name)
def test_each_kinds_values_are_its_own_options(kind: InputKind) -> None:
    assert [f.name for f in fields(kind.values)] == [o.name for o in kind.options]
    assert all(heading_of(o) == heading_of(kind.options[0]) for o in kind.options)


def test_every_registered_source_and_sink_is_made_by_an_option_of_predict() -> None:
    from semattnet.data.sources.registry import SOURCES
    from semattnet.inference.sinks import SINKS

    flags = {flag for p in predict.params for flag in p.opts}
    for registry in (SOURCES, SINKS):
        assert {e.option.split()[0] for e in registry.values() if e.option} <= flags, registry  # "--dataset void"


# -- a kind added to the table: its options, heading and the rule come with the entry alone ---------------------


@dataclass(frozen=True)
class _ToyInput(SourceOptions):
    heading: ClassVar[str] = "Inputs: toy"
    usage: ClassVar[str] = "--toy"
    selects: ClassVar[tuple[str, ...]] = ("toy",)
    accepts: ClassVar[tuple[str, ...]] = ("segment_spec",)

    toy: str | None = cli_option("--toy", help="A toy input.")
    toy_level: str | None = cli_option("--toy-level", help="Its level.")


_TOY = InputKind("toy", _ToyInput)
_KINDS = (*INPUTS, _TOY)


@click.command(cls=SectionedCommand)
@input_options(_KINDS)
def _toy_command(**params: object) -> None:
    chosen = choose_input(click.get_current_context(), _KINDS)
    click.echo(f"{chosen.kind.name}: {chosen.values}")


@pytest.mark.parametrize(
    ("args", "code", "said"),
    [
        (["--toy", "t", "--toy-level", "3", "--segment", "s"], 0, "toy: _ToyInput(toy='t', toy_level='3')"),
        (["--rgb", ".", "--sparse", ".", "--toy-level", "3"], 2, "--toy-level is an option of --toy, not of --rgb"),
        (["--toy", "t", "--frames", "1"], 2, "--frames is an option of --kitti-raw, not of --toy"),
        (["--toy", "t", "--semantic", "."], 2, "--semantic is an option of --rgb, --kitti-raw or --data, not of --toy"),
        (["--data", ".", "--toy", "t"], 2, "or --toy (one of them: not --data and --toy)"),
    ],
)
def test_a_new_input_kind_gets_the_rule_with_no_other_code(args: list[str], code: int, said: str) -> None:
    result = CliRunner().invoke(_toy_command, args)
    assert result.exit_code == code and said in result.output, result.output
    assert "Inputs: toy:\n  --toy TEXT" in CliRunner().invoke(_toy_command, ["--help"]).output
