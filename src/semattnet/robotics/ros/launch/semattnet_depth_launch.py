"""ROS 2 launch file of the semattnet depth node (installed with the package; needs ROS 2's ``launch`` and
``launch_ros``; the file itself imports nothing of semattnet, so ROS 2's Python runs it):

    LAUNCH=$(~/semattnet-venv/bin/python -c 'import semattnet.robotics.ros as r; print(r.__path__[0])')/launch
    ros2 launch "$LAUNCH/semattnet_depth_launch.py" params_file:=/etc/semattnet/depth.yaml namespace:=/robot \
        node_name:=depth executable:=$HOME/semattnet-venv/bin/semattnet

It uses ``launch_ros.actions.Node`` without ``package``: Node then runs ``executable`` as found on ``PATH`` (or a
full path: the ``executable`` argument, e.g. the virtual environment's ``bin/semattnet``), no ament index needed,
with ``arguments`` first and its ROS arguments after them: ``semattnet ros2 --ros-args -r __node:=NAME -r
__ns:=NS --params-file FILE``, which ``semattnet ros2`` reads as a ROS 2 node does.
"""

from __future__ import annotations

from pathlib import Path

#: The example parameter file beside this one (every key an option of ``semattnet ros2``).
EXAMPLE_PARAMS = str(Path(__file__).with_name("semattnet_depth.params.yaml"))


def generate_launch_description() -> object:
    """The launch description: arguments ``params_file``, ``namespace``, ``node_name``, ``executable``."""
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    arguments = [
        DeclareLaunchArgument("params_file", default_value=EXAMPLE_PARAMS, description="ROS 2 parameter file"),
        DeclareLaunchArgument("namespace", default_value="", description="the node's namespace"),
        DeclareLaunchArgument("node_name", default_value="semattnet", description="the node's name"),
        DeclareLaunchArgument("executable", default_value="semattnet", description="the semattnet command"),
    ]
    node = Node(
        executable=LaunchConfiguration("executable"),
        arguments=["ros2"],
        name=LaunchConfiguration("node_name"),
        namespace=LaunchConfiguration("namespace"),
        parameters=[LaunchConfiguration("params_file")],
        output="screen",
        sigterm_timeout="10",
    )
    return LaunchDescription([*arguments, node])
