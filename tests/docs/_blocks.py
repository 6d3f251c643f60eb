"""The code blocks of README.md and docs/**/*.md: found, classified (run / not run) and run.

A block runs unless the last non-blank line before its opening fence is an HTML comment
``<!-- not-run: REASON -->`` (data a user must download, a GPU, minutes of compute, ...).
Python blocks of one page share a namespace and run in order; shell blocks run in the page's
working folder, in order. A shell block whose every command is a ``semattnet`` command runs
through the click group in this process (the console script's entry point, without paying the
interpreter start-up per command); any other shell block runs in ``bash -euo pipefail`` with a
``semattnet`` on ``PATH`` that runs this checkout's package.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import types
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PYTHON_LANGS = {"python", "py"}
SHELL_LANGS = {"bash", "sh", "shell", "console"}
_FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>`{3,}|~{3,})[ \t]*(?P<lang>[\w+-]*)")
_NOT_RUN = re.compile(r"^\s*<!--\s*not-run:\s*(?P<reason>.*?)\s*-->\s*$")


@dataclass(frozen=True)
class Block:
    """One fenced block: where it is, its language, its code, and why it is not run (None: it runs)."""

    path: Path
    line: int
    lang: str
    code: str
    not_run: str | None

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(REPO)}:{self.line}"

    @property
    def counted(self) -> bool:
        """Python and shell blocks count; the rest (json, text, bibtex, ...) are not code to run."""
        return self.lang in PYTHON_LANGS | SHELL_LANGS


def markdown_files() -> list[Path]:
    """README.md and every page under docs/."""
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def parse_blocks(path: Path) -> list[Block]:
    """Every fenced block of one Markdown file (indented ones inside lists too)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = m["indent"], m["fence"], m["lang"].lower()
        start, body = i, []
        i += 1
        while i < len(lines) and not re.match(rf"^[ \t]*{re.escape(fence[0])}{{{len(fence)},}}\s*$", lines[i]):
            body.append(lines[i][len(indent) :] if lines[i].startswith(indent) else lines[i].lstrip())
            i += 1
        prev = next((lines[j] for j in range(start - 1, -1, -1) if lines[j].strip()), "")
        marker = _NOT_RUN.match(prev)
        blocks.append(Block(path, start + 1, lang, "\n".join(body) + "\n", marker["reason"] if marker else None))
        i += 1
    return blocks


def all_blocks() -> list[Block]:
    return [b for path in markdown_files() for b in parse_blocks(path)]


def shell_commands(code: str, lang: str) -> list[str]:
    """The commands of a shell block: continuation lines joined; for ``console``, the ``$ `` lines."""
    text = code.replace("\\\n", " ")
    lines = text.splitlines()
    if lang == "console":
        lines = [ln[2:] for ln in lines if ln.startswith("$ ")]
    return [ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]


def semattnet_argv(commands: list[str]) -> list[list[str]] | None:
    """Each command's arguments when every command is a plain ``semattnet ...`` call, else None."""
    argvs = []
    for command in commands:
        if any(ch in command for ch in "|&;<>$`()"):
            return None
        words = shlex.split(command, comments=True)
        if not words or words[0] != "semattnet":
            return None
        argvs.append(words[1:])
    return argvs


def run_semattnet(argv: list[str], where: str) -> None:
    """One ``semattnet`` command through the click group, as the console script runs it."""
    import torch

    from semattnet.cli import main

    threads = torch.get_num_threads()
    try:
        main.main(args=argv, prog_name="semattnet", standalone_mode=True)
    except SystemExit as exc:
        if exc.code not in (0, None):
            raise AssertionError(f"{where}: `semattnet {shlex.join(argv)}` exited with {exc.code}") from None
    finally:
        torch.set_num_threads(threads)


def shim_bin(folder: Path) -> Path:
    """A folder with a ``semattnet`` script that runs this checkout's package with this interpreter."""
    folder.mkdir(parents=True, exist_ok=True)
    script = folder / "semattnet"
    script.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m semattnet "$@"\n', encoding="utf-8")
    script.chmod(0o755)
    return folder


def run_bash(code: str, cwd: Path, env: dict[str, str], where: str) -> None:
    """A shell block in bash (-e, -u, pipefail); fails with its output when a command fails."""
    proc = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", code], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )
    if proc.returncode:
        tail = (proc.stdout + proc.stderr)[-3000:]
        raise AssertionError(f"{where}: shell block exited with {proc.returncode}:\n{tail}")


def run_page(blocks: list[Block], cwd: Path, env: dict[str, str]) -> int:
    """Run a page's runnable blocks in order in ``cwd``; returns how many ran."""
    page = types.ModuleType("__docs__")  # a module, so that a block may define dataclasses
    namespace: dict[str, object] = page.__dict__
    sys.modules[page.__name__] = page
    ran = 0
    old_cwd, old_env = Path.cwd(), dict(os.environ)
    os.chdir(cwd)
    os.environ.update(env)
    try:
        for block in blocks:
            if block.not_run is not None or not block.counted:
                continue
            if block.lang in PYTHON_LANGS:
                exec(compile(block.code, block.where, "exec"), namespace)
            else:
                commands = shell_commands(block.code, block.lang)
                argvs = semattnet_argv(commands)
                if argvs is None:
                    run_bash("\n".join(commands) + "\n", cwd, dict(os.environ), block.where)
                else:
                    for argv in argvs:
                        run_semattnet(argv, block.where)
            ran += 1
    finally:
        sys.modules.pop(page.__name__, None)
        os.chdir(old_cwd)
        os.environ.clear()
        os.environ.update(old_env)
    return ran
