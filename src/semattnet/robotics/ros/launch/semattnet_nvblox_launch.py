"""ROS 2 launch file: the semattnet depth node feeding nvblox (installed with the package; needs ROS 2's ``launch``
and ``launch_ros`` and Isaac ROS' ``nvblox_ros``; imports nothing of semattnet, docs/guides/nav2.md):

    LAUNCH=$(~/semattnet-venv/bin/python -c 'import semattnet.robotics.ros as r; print(r.__path__[0])')/launch
    ros2 launch "$LAUNCH/semattnet_nvblox_launch.py" executable:=$HOME/semattnet-venv/bin/semattnet

The node runs as ``semattnet_depth_launch.py`` runs it, with ``semattnet_nav2.params.yaml`` (a latched
camera_info); ``nvblox_node`` integrates its float depth (32FC1 metres) and camera_info, remapped from its
depth inputs (``camera_0/depth/...`` since Isaac ROS 3, ``depth/...`` before: both rules given, the one that names
no topic of nvblox is ignored) to the node's outputs ``NAMESPACE/NODE/output/...``.
"""

from __future__ import annotations

from pathlib import Path

#: The node's parameters for Nav2 and nvblox, beside this file.
NAV2_PARAMS = str(Path(__file__).with_name("semattnet_nav2.params.yaml"))
#: nvblox's depth inputs (Isaac ROS 3 on, and before) and the node's outputs they are remapped to.
NVBLOX_INPUTS = {
    "camera_0/depth/image": "depth_image",
    "camera_0/depth/camera_info": "camera_info",
    "depth/image": "depth_image",
    "depth/camera_info": "camera_info",
}


def generate_launch_description() -> object:
    """Arguments ``params_file``, ``namespace``, ``node_name``, ``executable`` (the node's) and ``global_frame``
    (nvblox's map frame)."""
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    arguments = [
        DeclareLaunchArgument("params_file", default_value=NAV2_PARAMS, description="the node's parameter file"),
        DeclareLaunchArgument("namespace", default_value="", description="the node's namespace"),
        DeclareLaunchArgument("node_name", default_value="semattnet", description="the node's name"),
        DeclareLaunchArgument("executable", default_value="semattnet", description="the semattnet command"),
        DeclareLaunchArgument("global_frame", default_value="odom", description="nvblox's map frame"),
    ]
    ns, name = LaunchConfiguration("namespace"), LaunchConfiguration("node_name")
    depth = Node(
        executable=LaunchConfiguration("executable"),
        arguments=["ros2"],
        name=name,
        namespace=ns,
        parameters=[LaunchConfiguration("params_file")],
        output="screen",
        sigterm_timeout="10",
    )
    nvblox = Node(
        package="nvblox_ros",
        executable="nvblox_node",
        name="nvblox_node",
        remappings=[(topic, [ns, "/", name, "/output/", output]) for topic, output in NVBLOX_INPUTS.items()],
        parameters=[
            {
                "global_frame": LaunchConfiguration("global_frame"),
                "use_depth": True,
                "use_color": False,
                "use_lidar": False,
                "input_qos": "SYSTEM_DEFAULT",
            }
        ],
        output="screen",
    )
    return LaunchDescription([*arguments, depth, nvblox])
