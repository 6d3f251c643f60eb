"""ROS command-line arguments and parameter files, read as ROS nodes read them (no click here: :mod:`semattnet.cli`
maps them onto a command's options).

- ROS 2 (``rcl``'s grammar): one or more ``--ros-args ... [--]`` sections holding ``-r``/``--remap FROM:=TO``
  (``__ns`` and ``__node`` set the namespace and the node name; ``NODE:FROM:=TO`` applies to node NODE only),
  ``-p``/``--param NAME:=VALUE`` (VALUE read as YAML), ``--params-file FILE``, ``--log-level [NAME:=]LEVEL``,
  ``-e``/``--enclave E``, ``--enable-rosout-logs`` / ``--disable-rosout-logs`` (the node's ``/rosout``, on by
  default) and the other log switches (accepted, no effect: the node writes no log files). Anything else in a
  section is refused in one line.
- ROS 1 (what ``rosrun`` and ``roslaunch`` pass): ``NAME:=VALUE`` words anywhere; ``__ns``, ``__name``,
  ``__master``, ``__ip``, ``__hostname`` set the node's own settings, ``__log`` is ignored, ``_KEY:=VALUE`` is a
  private parameter, any other ``FROM:=TO`` a remap.
- Parameter files: ROS 2's YAML, ``NODE: {ros__parameters: {KEY: VALUE}}``, where NODE is matched against the
  node's fully qualified name as ``rcl`` matches it: ``/**`` any node, ``*`` one name, ``**`` any number of names,
  a relative NODE is absolute from the root (``depth`` matches ``/depth`` only); nested mappings are ``a.b`` keys.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from semattnet._errors import InputError

__all__ = ["ROS1_SPECIALS", "RosArgs", "matches_node", "params_file_values", "split_ros_args", "yaml_value"]

#: ``--ros-args`` flags taking no value (the rosout pair turns ``/rosout`` on and off; the others have no effect: the
#: node writes no log files).
_LOG_SWITCHES = frozenset(
    f"--{on}-{what}-logs" for on in ("enable", "disable") for what in ("rosout", "stdout", "external-lib")
)
#: ROS 1 special names (``__ns:=``), by what they set.
ROS1_SPECIALS = {"__ns": "namespace", "__name": "node_name", "__master": "master", "__ip": "host", "__hostname": "host"}
_TOKEN = re.compile(r"[A-Za-z_~/][A-Za-z0-9_/~.]*")


@dataclass
class RosArgs:
    """What the ROS arguments asked: remaps (FROM, TO, and the node a ``NODE:FROM:=TO`` rule is for, else ""),
    parameters (NAME, VALUE as YAML text, where), files, and the node's settings (``namespace``, ``node_name``,
    ``master``, ``host``) a special remap gave."""

    remaps: list[tuple[str, str, str]] = field(default_factory=list)
    params: list[tuple[str, str, str]] = field(default_factory=list)
    params_files: list[Path] = field(default_factory=list)
    settings: dict[str, str] = field(default_factory=dict)
    log_level: str | None = None
    enclave: str | None = None
    rosout: bool = True


def _rule(text: str, flag: str) -> tuple[str, str]:
    """``FROM:=TO`` -> (FROM, TO); a one-line error else."""
    left, sep, right = text.partition(":=")
    if not sep or not left or not right:
        raise InputError(f"{flag} {text!r}: expected NAME:=VALUE")
    return left, right


def _remap(ros: RosArgs, text: str) -> None:
    """One ``-r`` rule: ``__ns`` / ``__node`` / ``__name`` set the node's names; ``NODE:FROM:=TO`` is kept with
    its NODE (it applies to that node only)."""
    left, right = _rule(text, "--remap")
    target, colon, name = left.rpartition(":")
    if colon and target and not target.startswith("__"):
        left = name
    else:
        target = ""
    if left == "__ns":
        ros.settings["namespace"] = right
    elif left in ("__node", "__name"):
        ros.settings["node_name"] = right
    elif left.startswith("__"):
        raise InputError(f"--remap {text!r}: {left} is not a remap this node takes (__ns, __node)")
    elif not _TOKEN.fullmatch(left) or not _TOKEN.fullmatch(right):
        raise InputError(f"--remap {text!r}: expected FROM:=TO of ROS names (e.g. ~/input/image:=/camera/image_raw)")
    else:
        ros.remaps.append((left, right, target))


def _section(words: list[str], at: int, ros: RosArgs) -> int:
    """Read one ``--ros-args`` section from ``words[at]`` (after the flag); the index after it."""
    takes = {"-r", "--remap", "-p", "--param", "--params-file", "--log-level", "-e", "--enclave", "--log-config-file"}
    i = at
    while i < len(words):
        word = words[i]
        if word == "--":
            return i + 1
        if word == "--ros-args":
            i += 1
            continue
        if word in _LOG_SWITCHES:
            if word in ("--enable-rosout-logs", "--disable-rosout-logs"):
                ros.rosout = word == "--enable-rosout-logs"
            i += 1
            continue
        if word not in takes:
            raise InputError(f"--ros-args: {word!r} is not an argument this node takes (see `semattnet ros2 --help`)")
        if i + 1 >= len(words):
            raise InputError(f"--ros-args: {word} needs a value")
        value = words[i + 1]
        if word in ("-r", "--remap"):
            _remap(ros, value)
        elif word in ("-p", "--param"):
            name, text = _rule(value, "--param")
            ros.params.append((name, text, f"-p {value}"))
        elif word == "--params-file":
            ros.params_files.append(Path(value))
        elif word == "--log-level":
            ros.log_level = value.rpartition(":=")[2]
        elif word in ("-e", "--enclave"):
            ros.enclave = value
        else:
            raise InputError(f"--ros-args: {word} is not supported by this node (it logs with Python's logging)")
        i += 2
    return i


def split_ros_args(argv: list[str], ros1: bool = False) -> tuple[list[str], RosArgs]:
    """``argv`` without its ROS arguments, and what they asked (module doc); ``ros1``: ``NAME:=VALUE`` words too.

    >>> rest, ros = split_ros_args(["--frames", "3", "--ros-args", "-r", "__ns:=/robot", "-p", "max_skew:=0.05"])
    >>> rest, ros.settings, ros.params
    (['--frames', '3'], {'namespace': '/robot'}, [('max_skew', '0.05', '-p max_skew:=0.05')])
    """
    ros, rest, i = RosArgs(), [], 0
    while i < len(argv):
        word = argv[i]
        if word == "--ros-args":
            i = _section(argv, i + 1, ros)
            continue
        if ros1 and ":=" in word and not word.startswith("-"):
            _ros1_word(ros, word)
        else:
            rest.append(word)
        i += 1
    return rest, ros


def _ros1_word(ros: RosArgs, word: str) -> None:
    """One ROS 1 ``NAME:=VALUE`` word (module doc)."""
    name, value = _rule(word, "ROS 1 argument")
    if name in ROS1_SPECIALS:
        ros.settings[ROS1_SPECIALS[name]] = value
    elif name == "__log":
        return
    elif name.startswith("__"):
        raise InputError(f"{word!r}: {name} is not a ROS 1 special name this node takes ({', '.join(ROS1_SPECIALS)})")
    elif name.startswith("_"):
        ros.params.append((name[1:], value, word))
    else:
        _remap(ros, word)


def yaml_value(text: str, where: str) -> object:
    """A ``-p`` value read as YAML, as ``rcl`` reads it (``0.5`` a float, ``true`` a bool, ``a`` a string)."""
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise InputError(f"{where}: not a YAML value ({str(exc).splitlines()[0]})") from None


def matches_node(pattern: str, fqn: str) -> bool:
    """Whether a parameter file's NODE key selects the node ``fqn`` (``/ns/name``), as ``rcl`` matches it.

    >>> tuple(k for k in ("/**", "/robot/depth", "depth", "/*/depth", "/**/x") if matches_node(k, "/robot/depth"))
    ('/**', '/robot/depth', '/*/depth')
    """
    key = pattern if pattern.startswith("/") else "/" + pattern
    parts = []
    for part in key.strip("/").split("/"):
        if part == "**":
            parts.append(r"(?:/[^/]+)*")
        else:
            parts.append("/" + re.escape(part).replace(r"\*", "[^/]+"))
    return re.fullmatch("".join(parts), fqn) is not None


def _flatten(values: dict[object, object], prefix: str = "") -> list[tuple[str, object]]:
    out: list[tuple[str, object]] = []
    for key, value in values.items():
        name = f"{prefix}{key}"
        out += _flatten(value, name + ".") if isinstance(value, dict) else [(name, value)]
    return out


def params_file_values(path: Path, fqn: str) -> list[tuple[str, object, str]]:
    """The (key, value, where) pairs of a ROS 2 parameter file that apply to the node ``fqn``, in file order.

    Raises:
        InputError: an unreadable file, not YAML, or not ``NODE: {ros__parameters: {...}}``; naming the file.
    """
    import yaml

    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"--params-file {path}: cannot read it ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise InputError(f"--params-file {path}: not YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected NODE_NAME: {{ros__parameters: {{...}}}} at the top")
    out: list[tuple[str, object, str]] = []
    for node, body in doc.items():
        if (
            not isinstance(body, dict)
            or set(body) != {"ros__parameters"}
            or not isinstance(body["ros__parameters"], dict)
        ):
            raise InputError(f"{path}: {node}: expected a mapping holding only ros__parameters: {{KEY: VALUE}}")
        if matches_node(str(node), fqn):
            out += [(key, value, f"{path}: {node}: {key}") for key, value in _flatten(body["ros__parameters"])]
    return out
