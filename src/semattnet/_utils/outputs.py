"""The output policy every command (and the library functions behind them) follows.

0. The one rule, :func:`check_outputs`: no output is, contains or lies inside an input, nor another output
   of the same run (a folder the run writes named files into may hold its other outputs); ``overwrite``
   replaces only what is recognisably an earlier output of ours (:data:`KINDS`), never a user's folder or file.
1. Nothing existing is replaced unless ``overwrite=True`` (checked before any work).
2. Outputs never go into an input: an output folder equal to or inside an input folder (the
   folder of an input file counts) and an output file that resolves to an input are refused.
3. Multi-file outputs are staged in a hidden folder inside the output folder and moved into
   place only when every file was written: an error (a corrupt frame) or a kill writes nothing.
   Stage folders a kill left behind are removed by the next staged write into the same folder.
4. Generated trees (``synth``, ``data download``) carry a marker, :data:`TREE_MARKER`, written as
   "started" first and rewritten as "complete" last: a tree whose marker is not complete was cut short
   (a kill, a full disk) and ``data check`` refuses it (:func:`incomplete_tree`).
5. Single files are written atomically (:func:`semattnet._utils.atomic.atomic_path`): umask mode,
   fsynced, orphaned temporary files cleaned on the next write of the same target.
6. A run that writes into a folder over time (``predict``) holds :class:`~semattnet._utils.lock.FolderLock` on
   it: a second run into the same folder is refused while the first one runs.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from semattnet._errors import SemAttNetError
from semattnet._utils.atomic import atomic_path, disk_full_error, fsync_dir, is_disk_full, is_named_disk_full

__all__ = [
    "BAG_MARKER",
    "KINDS",
    "STAGE_PREFIX",
    "TREE_MARKER",
    "Output",
    "OutputError",
    "bag_mark",
    "check_no_input_overlap",
    "check_outputs",
    "clean_stale_stages",
    "incomplete_tree",
    "mark_bag_file",
    "mark_tree",
    "refuse_existing",
    "stage_folder",
    "staged_outputs",
    "write_text",
]

#: Hidden staging folders inside an output folder: ``.semattnet-stage.XXXXXXXX``.
STAGE_PREFIX = ".semattnet-stage."

#: The completion marker of a generated tree (JSON: generator, complete, resume).
TREE_MARKER = ".semattnet-tree.json"

#: The marker file inside a ROS 2 bag folder semattnet wrote: what lets ``--overwrite`` replace it. A ROS 1
#: ``NAME.bag`` file semattnet wrote has it beside it instead, as ``.NAME.bag.semattnet-bag``: its size and
#: modification time (:func:`mark_bag_file`), so a user's recording put in its place is not taken for ours.
BAG_MARKER = ".semattnet-bag"


class OutputError(SemAttNetError):
    """An output that would replace or land inside the command's own inputs."""


def _resolve(path: str | os.PathLike[str]) -> Path:
    return Path(path).expanduser().resolve()


def refuse_existing(paths: Iterable[str | os.PathLike[str]], overwrite: bool) -> None:
    """Raise :class:`FileExistsError` naming the first of ``paths`` that exists, unless ``overwrite``."""
    if overwrite:
        return
    existing = [Path(p) for p in paths if Path(p).exists()]
    if existing:
        more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
        raise FileExistsError(f"{existing[0]} exists{more}; pass --overwrite (overwrite=True) to replace it")


def _inode(path: Path) -> tuple[int, int] | None:
    """(device, inode) of ``path`` (symlinks followed), None when it does not exist."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino


def check_no_input_overlap(
    inputs: Iterable[str | os.PathLike[str] | None],
    out_dir: str | os.PathLike[str] | None = None,
    out_files: Iterable[str | os.PathLike[str]] = (),
) -> None:
    """Refuse ``out_dir`` equal to or inside an input folder, and any of ``out_files`` that is an
    input file (by resolved path and by inode, as :func:`os.path.samefile`: hard links count) or an
    existing file inside an input folder (symlinks are followed). Holds with ``overwrite=True`` too.

    Raises:
        OutputError: naming the output and the input it collides with.
    """
    folders: list[Path] = []
    files: dict[Path | tuple[int, int], Path] = {}
    for item in inputs:
        if item is None:
            continue
        p = _resolve(item)
        if p.is_dir():
            folders.append(p)
        else:
            files[p] = p
            if (ino := _inode(p)) is not None:
                files[ino] = p
    if out_dir is not None:
        o, o_ino = _resolve(out_dir), _inode(Path(out_dir))
        for folder in folders:
            if o == folder or o.is_relative_to(folder) or (o_ino is not None and o_ino == _inode(folder)):
                raise OutputError(
                    f"output folder {out_dir} is the input folder {folder} or inside it; "
                    "choose an --out outside the inputs"
                )
    for f in out_files:
        r = _resolve(f)
        ino = _inode(r)
        hit = files.get(r) or (files.get(ino) if ino is not None else None)
        if hit is None and ino is not None and any(r.is_relative_to(folder) for folder in folders):
            hit = r
        if hit is None and ino is not None and folders and r.stat().st_nlink > 1:
            hit = _linked_input(ino, folders)  # a hard link to a file inside an input folder
        if hit is not None:
            raise OutputError(f"output {f} would replace the input {hit}; choose another output path")


def _linked_input(ino: tuple[int, int], folders: list[Path]) -> Path | None:
    """The file under ``folders`` with inode ``ino`` (only looked for when an output is a hard link)."""
    for folder in folders:
        for p in folder.rglob("*"):
            if p.is_file() and _inode(p) == ino:
                return p
    return None


def clean_stale_stages(folder: Path, prefix: str = STAGE_PREFIX) -> None:
    """Remove the stage folders ``PREFIX<pid>.*`` in ``folder`` that a killed run left (their process is gone)."""
    from semattnet._utils.atomic import pid_alive

    for entry in folder.glob(f"{prefix}*"):
        pid = entry.name[len(prefix) :].split(".")[0]
        if entry.is_dir() and pid.isdigit() and not pid_alive(int(pid)):
            shutil.rmtree(entry, ignore_errors=True)


@contextmanager
def stage_folder(out: Path) -> Iterator[Path]:
    """This process's hidden stage folder inside ``out`` (created, with the stale ones of killed runs removed
    first), removed again on exit. A full disk inside the block is the one-line
    :func:`~semattnet._utils.atomic.disk_full_error` naming ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    clean_stale_stages(out)
    stage = Path(tempfile.mkdtemp(prefix=f"{STAGE_PREFIX}{os.getpid()}.", dir=out))
    try:
        yield stage
    except OSError as exc:
        if not is_disk_full(exc) or exc.filename == str(out) or is_named_disk_full(exc):
            raise
        staged = sum(p.stat().st_size for p in stage.rglob("*") if p.is_file())
        raise disk_full_error(out, staged + 1) from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)


@contextmanager
def staged_outputs(out: str | os.PathLike[str], overwrite: bool = False) -> Iterator[Path]:
    """Yield a hidden folder inside ``out``; write the outputs there (same relative names). When
    the block succeeds every file moves into ``out`` (refusing existing ones unless ``overwrite``,
    checked before the first move); when it raises, or the process dies, ``out`` is unchanged (a folder
    it created is removed again; a full disk raises :func:`~semattnet._utils.atomic.disk_full_error`)."""
    out = Path(out)
    created = not out.exists()
    try:
        with stage_folder(out) as stage:
            yield stage
            files = sorted(p for p in stage.rglob("*") if p.is_file())
            refuse_existing((out / p.relative_to(stage) for p in files), overwrite)
            for p in files:
                target = out / p.relative_to(stage)
                target.parent.mkdir(parents=True, exist_ok=True)
                os.replace(p, target)
            fsync_dir(out)
    finally:
        if created and out.is_dir() and not any(out.iterdir()):
            out.rmdir()  # a failed run leaves no empty folder it made


def write_text(path: str | os.PathLike[str], text: str, overwrite: bool = False) -> Path:
    """Write ``text`` to ``path`` atomically; refuses an existing file unless ``overwrite``."""
    path = Path(path)
    refuse_existing([path], overwrite)
    with atomic_path(path, suffix=path.suffix) as tmp:
        tmp.write_text(text)
    return path


def mark_tree(root: str | os.PathLike[str], generator: str, complete: bool, resume: str = "") -> Path:
    """Write ``root``/:data:`TREE_MARKER` atomically: call with ``complete=False`` before the first
    file of a generated tree and with ``complete=True`` after the last; ``resume`` says how to finish
    a tree that was cut short (e.g. the command to run again)."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    doc = {"generator": generator, "complete": complete, "resume": resume}
    with atomic_path(root / TREE_MARKER, suffix=".json") as tmp:
        tmp.write_text(json.dumps(doc))
    return root / TREE_MARKER


def incomplete_tree(root: str | os.PathLike[str]) -> str | None:
    """A one-line message when ``root`` holds a generated tree whose marker is not "complete" (a
    generator was killed or failed), else None (complete, or not a tree we generated)."""
    marker = Path(root) / TREE_MARKER
    if not marker.is_file():
        return None
    try:
        doc = json.loads(marker.read_text())
        if doc.get("complete") is True:
            return None
        generator, resume = str(doc.get("generator", "?")), str(doc.get("resume", ""))
    except (OSError, ValueError, AttributeError):
        generator, resume = "?", ""
    how = f"; to finish it: {resume}" if resume else "; generate it again"
    return f"{root}: incomplete tree (the {generator} that wrote it was interrupted; {marker} is not complete){how}"


def _head(path: Path, n: int = 16) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(n)
    except OSError:
        return b""


def _is_safetensors(path: Path) -> bool:
    head = _head(path, 9)
    return len(head) == 9 and int.from_bytes(head[:8], "little") < path.stat().st_size and head[8:] == b"{"


def bag_mark(path: str | os.PathLike[str]) -> Path:
    """Where the mark of the ROS 1 bag file ``path`` goes (:func:`mark_bag_file`): ``.NAME.semattnet-bag`` beside it."""
    path = Path(path)
    return path.parent / f".{path.name}{BAG_MARKER}"


def _stamp(path: Path) -> dict[str, int]:
    st = path.lstat()
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns, "inode": st.st_ino}


def mark_bag_file(path: str | os.PathLike[str]) -> None:
    """Record the ROS 1 bag file ``path`` (just written by semattnet) beside it, so that ``--overwrite`` may
    replace it later: the file ``.NAME.semattnet-bag`` with its size, modification time and inode."""
    path = Path(path)
    with atomic_path(bag_mark(path), suffix=".json") as tmp:
        tmp.write_text(json.dumps(_stamp(path)) + "\n")


def _is_bag(path: Path) -> bool:
    """A ROS 2 bag folder carrying :data:`BAG_MARKER`, or a ROS 1 bag file that its mark beside it describes
    (:func:`mark_bag_file`): what semattnet wrote, recognised by its mark, never by a format's magic bytes."""
    if path.is_dir():
        return (path / BAG_MARKER).is_file() and (path / "metadata.yaml").is_file()
    try:
        return path.is_file() and not path.is_symlink() and json.loads(bag_mark(path).read_text()) == _stamp(path)
    except (OSError, ValueError, RecursionError):
        return False


def _is_file(magic: bytes) -> Callable[[Path], bool]:
    return lambda p: p.is_file() and _head(p, len(magic)) == magic


#: What an existing output must be for ``overwrite`` to replace it, by kind: (what it is, the test).
#: ``folder``: a folder the run writes named files into (it may exist; the files are outputs of their own);
#: ``file``: one of those files (any regular file of that name, never a folder).
KINDS: dict[str, tuple[str, Callable[[Path], bool]]] = {
    "folder": ("a folder", Path.is_dir),
    "file": ("a regular file", Path.is_file),
    "tree": (f"a tree semattnet generated ({TREE_MARKER} in it)", lambda p: (p / TREE_MARKER).is_file()),
    "bag": (f"a bag semattnet wrote ({BAG_MARKER} in it, or beside a ROS 1 .bag file)", _is_bag),
    "json": ("a JSON file", lambda p: p.is_file() and _head(p, 64).lstrip()[:1] in (b"{", b"[")),
    "rrd": ("a Rerun recording", _is_file(b"RRF")),
    "ply": ("a PLY file", _is_file(b"ply")),
    "png": ("a PNG image", _is_file(b"\x89PNG")),
    "zip": ("a zip archive", _is_file(b"PK\x03\x04")),
    "safetensors": ("a safetensors file", lambda p: p.is_file() and _is_safetensors(p)),
}


@dataclass(frozen=True)
class Output:
    """One output of a run for :func:`check_outputs`: the option that names it (``--bag-out``), its path and
    its kind (a key of :data:`KINDS`: what an existing one must be for ``overwrite`` to replace it)."""

    option: str
    path: str | os.PathLike[str]
    kind: str = "file"


def _named(option: str, path: object) -> str:
    return f"{option} {path}" if option else str(path)


def check_outputs(
    inputs: Iterable[tuple[str, str | os.PathLike[str] | None]], outputs: Iterable[Output], overwrite: bool = False
) -> None:
    """The one output rule, checked before any work. ``inputs``: (option, path) pairs (None paths ignored).

    * No output is an input (by resolved path or, hard links, by inode), lies inside an input, or contains one.
    * No two outputs are one path, and none lies inside another (only inside a ``folder`` output, and then it
      resolves inside it: a subfolder that is a symlink out of the folder is refused).
    * An existing output is refused unless ``overwrite``; with it, only one that is recognisably an earlier
      output of ours (:data:`KINDS`): never a user's folder or file.

    Raises:
        OutputError: naming the output's option and path and the input or output it collides with.
        FileExistsError: an output exists and not ``overwrite``.
    """
    outs = [(o, _resolve(o.path)) for o in outputs]
    ins: dict[Path | tuple[int, int], tuple[str, Path]] = {}
    for option, p in inputs:
        if p is not None:
            ins[_resolve(p)] = (option, Path(p))
            if (ino := _inode(Path(p))) is not None and not Path(p).is_dir():
                ins[ino] = (option, Path(p))
    by_path: dict[Path, Output] = {}
    for o, r in outs:
        _against_inputs(o, r, ins)
        if r in by_path:
            raise OutputError(
                f"{_named(o.option, o.path)} and {_named(by_path[r].option, by_path[r].path)} are "
                "one path; choose distinct paths"
            )
        by_path[r] = o
    for o, r in outs:
        outer = next((by_path[p] for p in r.parents if p in by_path and by_path[p].kind != "folder"), None)
        if outer is not None:
            what = "the output folder" if o.kind == "folder" else "the output"
            raise OutputError(
                f"{_named(outer.option, outer.path)} would replace {what} {_named(o.option, o.path)} "
                "(it holds it); choose distinct paths"
            )
    _inside_folders(outs)
    for (option, given), r in ((v, k) for k, v in ins.items() if isinstance(k, Path)):
        holder = next((by_path[p] for p in r.parents if p in by_path), None)
        if holder is not None:
            raise OutputError(
                f"{_named(holder.option, holder.path)} holds the input {_named(option, given)}; "
                "choose an output path that holds no input"
            )
    _check_replaceable([o for o, _ in outs], overwrite)


def _inside_folders(outs: list[tuple[Output, Path]]) -> None:
    """Every output named inside a ``folder`` output lands inside it (no symlinked subfolder leads out of it),
    with ``overwrite`` too: a file in someone else's folder is never replaced. (An output that is itself a
    symlink is replaced by the new file, its target untouched.)"""
    folders = [(o, Path(os.path.abspath(o.path)), r) for o, r in outs if o.kind == "folder"]
    for o, _ in outs:
        named = Path(os.path.abspath(o.path))
        lands = _resolve(named.parent) / named.name
        for f, f_named, f_resolved in folders:
            if named != f_named and named.is_relative_to(f_named) and not lands.is_relative_to(f_resolved):
                steps = [p for p in [*reversed(named.parents), named] if p != f_named and p.is_relative_to(f_named)]
                link = next((p for p in steps if p.is_symlink()), named)
                raise OutputError(
                    f"{_named(o.option, o.path)} lies outside {_named(f.option, f.path)}: {link} "
                    f"is a symbolic link to {_resolve(link)}; remove the link or choose another "
                    "--out"
                )


def _against_inputs(o: Output, r: Path, ins: dict[Path | tuple[int, int], tuple[str, Path]]) -> None:
    """``o`` (resolved ``r``) is no input and lies inside none."""
    ino = _inode(r)
    hit = ins.get(r) or (ins.get(ino) if ino is not None and not r.is_dir() else None)
    if hit is not None:
        what = "the input folder" if r.is_dir() else "the input"
        raise OutputError(f"{_named(o.option, o.path)} would replace {what} {_named(*hit)}; choose another path")
    inside = next((ins[p] for p in r.parents if p in ins), None)
    if inside is not None:
        raise OutputError(
            f"{_named(o.option, o.path)} lies inside the input folder {_named(*inside)}; "
            "choose a path outside the inputs"
        )


def _check_replaceable(outs: list[Output], overwrite: bool) -> None:
    """Existing outputs: none without ``overwrite``; with it, only those of their kind (a folder stays)."""
    for o in outs:
        p = Path(o.path)
        if o.kind == "folder" and p.exists() and not p.is_dir():
            raise OutputError(f"{_named(o.option, p)} is a file, not a folder; choose a folder path")
    existing = [o for o in outs if o.kind != "folder" and (Path(o.path).exists() or Path(o.path).is_symlink())]
    refuse_existing([o.path for o in existing], overwrite)
    for o in existing:
        what, test = KINDS[o.kind]
        p = Path(o.path)
        if not test(p) and not (p.is_dir() and not p.is_symlink() and not any(p.iterdir())):  # empty: nothing lost
            raise OutputError(
                f"{_named(o.option, p)} exists and is not {what}; --overwrite replaces only an "
                "earlier output of semattnet, never a user's folder or file: move it or choose "
                "another path"
            )
