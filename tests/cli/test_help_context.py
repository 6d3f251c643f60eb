"""Each option's help says what it does for the command it is on (issue 55, item 5): no option's help names an
option that its command lacks (a shared option's text written for another command)."""

from __future__ import annotations

import re
from collections.abc import Iterator

import click

from semattnet.cli import main


def _commands(cmd: click.Command, path: tuple[str, ...] = ()) -> Iterator[tuple[str, click.Command]]:
    if isinstance(cmd, click.Group):
        for name, sub in cmd.commands.items():
            yield from _commands(sub, (*path, name))
    else:
        yield " ".join(path), cmd


def foreign_flags(help_text: str, flags: set[str]) -> list[str]:
    """The options ``help_text`` names that are not in ``flags`` (a named other command's options left out)."""
    text = re.sub(r"`semattnet [^`]*`", "", help_text)
    return [f for f in re.findall(r"(?<![\w-])--[a-z][\w-]*", text) if f not in flags]


def test_no_option_help_names_an_option_its_command_lacks() -> None:
    found = []
    for name, cmd in _commands(main):
        params = cmd.get_params(click.Context(cmd, info_name=name))
        flags = {f for p in params for f in (*p.opts, *p.secondary_opts)}
        for p in params:
            found += [f"{name} {p.opts[0]}: names {f}" for f in foreign_flags(getattr(p, "help", None) or "", flags)]
    assert not found, "\n".join(found)


def test_the_check_sees_a_foreign_option_and_not_another_commands() -> None:
    assert foreign_flags("With --kitti-raw: segment (see `semattnet segment --model`).", {"--segment"}) == [
        "--kitti-raw"
    ]
    assert foreign_flags("Also --segment.", {"--segment"}) == []
