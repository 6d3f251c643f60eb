"""``ros2`` / ``ros1``'s ROS front: ``--ros-args`` (and ROS 1's ``NAME:=VALUE`` words), parameter files and ``-p``
mapped onto the command's own options (:mod:`semattnet.robotics.ros.ros_args` reads them).

Every option of the command is a parameter named as the option with ``_`` for ``-`` (``--max-skew``:
``max_skew``), its value checked by the option's own click type, so an option added to the command is a
parameter at once. Who wins, lowest first: the option's default, the parameter files in order (the plain
``--params-file`` ones, then those of ``--ros-args``; in a file, its matching sections in file order), the
``-p`` values in order, then an option given on the command line (``-r __ns:=`` / ``__node:=`` count as
given). Topic remaps replace the topic options they match (compared as resolved names).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import click

from semattnet._errors import InputError
from semattnet.cli._params import GeneratedCommand, section

if TYPE_CHECKING:
    from semattnet.robotics.ros.ros_args import RosArgs

__all__ = ["PARAMS_OPTIONS", "TOPIC_OPTIONS", "Ros1NodeCommand", "RosNodeCommand", "settable_params"]

#: The options that name a topic (a remap whose FROM is one of them replaces it).
TOPIC_OPTIONS = ("image_topic", "camera_info_topic", "points_topic", "output_prefix")
#: What the parameters cannot set: the parameter files themselves.
_NOT_PARAMETERS = frozenset({"params_file"})

PARAMS_OPTIONS = (
    section("ROS")(
        ["--params-file"],
        type=click.Path(exists=True, dir_okay=False, path_type=Path),
        multiple=True,
        help="A ROS 2 parameter file (NODE: {ros__parameters: {KEY: VALUE}}; KEY an option's name with _ for -); "
        "several: the later wins; an option given on the command line wins over them.",
    ),
)


def settable_params(command: click.Command, ctx: click.Context) -> dict[str, click.Parameter]:
    """The command's options a parameter file or ``-p`` sets, by parameter name."""
    return {p.name: p for p in command.get_params(ctx) if p.name and p.expose_value and p.name not in _NOT_PARAMETERS}


class RosNodeCommand(GeneratedCommand):
    """A ROS 2 node command (``ros2``) whose arguments may hold ROS arguments (module doc)."""

    #: Whether ROS 1's ``NAME:=VALUE`` words are read too (:class:`Ros1NodeCommand`).
    ros1 = False

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        from semattnet.robotics.ros.ros_args import split_ros_args

        try:
            rest, ros = split_ros_args(list(args), ros1=self.ros1)
        except InputError as exc:
            raise click.UsageError(str(exc), ctx) from None
        out = super().parse_args(ctx, rest)
        if ctx.resilient_parsing:
            return out
        try:
            self._apply(ctx, ros)
        except InputError as exc:
            raise click.UsageError(str(exc), ctx) from None
        return out

    def _apply(self, ctx: click.Context, ros: RosArgs) -> None:
        """Set the options from the ROS arguments (module doc)."""
        from semattnet.robotics.ros.ros_args import params_file_values, yaml_value

        params = settable_params(self, ctx)
        given = {name for name in params if ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE}
        namespace = os.environ.get("ROS_NAMESPACE", "").strip()
        if self.ros1 and namespace and "namespace" not in given:  # roslaunch's <node ns=...>, as rospy reads it
            ros.settings.setdefault("namespace", namespace)
        for name, setting in ros.settings.items():
            if name not in params:
                raise InputError(f"{name}: not a setting of semattnet {ctx.info_name}")
            ctx.params[name] = _converted(ctx, params[name], setting, f"the ROS argument for {name}")
            given.add(name)
        fqn = _fqn(ctx)
        values: list[tuple[str, object, str]] = []
        for path in [*ctx.params.get("params_file", ()), *ros.params_files]:
            values += params_file_values(Path(path), fqn)
        values += [(name, yaml_value(text, where), where) for name, text, where in ros.params]
        values = _qos_overrides(ctx, values, self.ros1)
        for key, value, where in values:
            if key not in params:
                raise InputError(
                    f"{where}: not a parameter of semattnet {ctx.info_name} (a parameter is one of its options, "
                    f"named with _ for -, e.g. max_skew)"
                )
            converted = _converted(ctx, params[key], value, where)
            if key not in given:
                ctx.params[key] = converted
        node = str(ctx.params["node_name"]).strip("/")
        _remap_topics(ctx, [(source, to) for source, to, target in ros.remaps if target in ("", node)])
        if ros.log_level is not None:
            _log_level(ros.log_level)
        ctx.meta["semattnet.enclave"] = ros.enclave or "/"
        ctx.meta["semattnet.rosout"] = ros.rosout


class Ros1NodeCommand(RosNodeCommand):
    """``ros1``: ROS 1's ``NAME:=VALUE`` words (``__ns:=``, ``__name:=``, ``_key:=``, remaps) read too, and
    ``ROS_NAMESPACE`` (what roslaunch sets for ``<node ns=...>``) where neither ``__ns:=`` nor ``--namespace``
    names the namespace."""

    ros1 = True


def _qos_overrides(
    ctx: click.Context, values: list[tuple[str, object, str]], ros1: bool
) -> list[tuple[str, object, str]]:
    """The ``values`` other than ``qos_overrides.TOPIC.ENTITY.POLICY`` ones, which become ``--qos`` overrides before
    the command line's (a ``--qos`` given wins); ``ros1`` refuses them (ROS 1 has no QoS)."""
    from semattnet.robotics.ros.qos import QOS_PREFIX, ROS1_NO_QOS, qos_override_param

    rest, overrides = [], []
    for key, value, where in values:
        if not key.startswith(QOS_PREFIX):
            rest.append((key, value, where))
        elif ros1:
            raise InputError(f"{where}: {ROS1_NO_QOS}")
        else:
            overrides.append(qos_override_param(key, value, where))
    if overrides:
        ctx.params["qos"] = (tuple(overrides), *ctx.params.get("qos", ()))
    return rest


def _converted(ctx: click.Context, param: click.Parameter, value: object, where: str) -> object:
    """``value`` through ``param``'s click type (and callback); a one-line error naming ``where``."""
    if isinstance(value, list) and not param.multiple and param.nargs == 1:
        raise InputError(f"{where}: expected one value, not a list")
    if param.multiple and not isinstance(value, list):
        value = [value]
    try:
        return param.process_value(ctx, value)
    except click.BadParameter as exc:
        raise InputError(f"{where}: {exc.message}") from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}: {value!r} is not a value of {param.type.name} ({exc})") from None


def _fqn(ctx: click.Context) -> str:
    """The node's fully qualified name (``/ns/name``) from its options as they stand."""
    from semattnet.robotics.ros.names import check_namespace

    return check_namespace(str(ctx.params.get("namespace") or "")) + "/" + str(ctx.params["node_name"]).strip("/")


def _remap_topics(ctx: click.Context, remaps: Sequence[tuple[str, str]]) -> None:
    """Each topic option that a remap's FROM names (resolved as the node resolves it) becomes the remap's TO; the
    first matching rule wins, as in ``rcl``; a rule that names no topic of the node is left alone (launch files
    pass rules for several nodes). A single output topic is refused: ``~/output`` (the prefix) is remapped."""
    from semattnet.robotics.frame import TOPICS
    from semattnet.robotics.ros.names import resolve_name

    if not remaps:
        return
    ns, node = str(ctx.params.get("namespace") or ""), str(ctx.params["node_name"])

    def resolved(name: str, what: str = "--remap") -> str:
        return resolve_name("~/" + name[1:].lstrip("/") if name.startswith("~") else name, ns, node, what)

    rules = [(resolved(a), resolved(b), a) for a, b in remaps]
    outputs = {f"{resolved(str(ctx.params['output_prefix']))}/{t}" for t in TOPICS.values()}
    for source, _, text in rules:
        if source in outputs:
            raise InputError(f"--remap {text}: one output topic cannot be remapped; remap ~/output (the prefix)")
    for option in TOPIC_OPTIONS:
        current = resolved(str(ctx.params[option]), "--" + option.replace("_", "-"))
        target = next((b for a, b, _ in rules if a == current), None)
        if target is not None:
            ctx.params[option] = target


def _log_level(level: str) -> None:
    """``--log-level``: the level of semattnet's loggers (ROS's names, any case)."""
    names = {"debug": logging.DEBUG, "info": logging.INFO, "warn": logging.WARNING, "warning": logging.WARNING}
    names |= {"error": logging.ERROR, "fatal": logging.CRITICAL, "unset": logging.NOTSET}
    if level.lower() not in names:
        raise InputError(f"--log-level {level!r}: expected one of {', '.join(sorted(names))}")
    logging.getLogger("semattnet").setLevel(names[level.lower()])
