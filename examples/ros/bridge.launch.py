"""Launch the slr bridge with ROS 2's launch system (needs a ROS 2 installation with the
`launch` package; the pip wheels of rclpy do not bring it).

    ros2 launch examples/ros/bridge.launch.py db:=robot.db map:=examples/ros/robot.yaml
    ros2 launch examples/ros/bridge.launch.py db:=robot.db all_topics:=true node_name:=slr

It runs `slr ros bridge DB --ros-args -p map:=MAP -p all_topics:=BOOL -r __node:=NAME`:
the MAP file and `all_topics` as the node's ROS parameters (docs/ros.md, "The live bridge").
"""
from pathlib import Path

HERE = Path(__file__).resolve().parent


def bridge_command(db, mapping, all_topics, node_name) -> list:
    """The bridge's command line; each argument a string or a launch substitution.

    Kept apart from the launch description so that it can be read (and run) without ROS 2's
    `launch` package: tests run exactly this command with a real ROS node.

    >>> bridge_command("robot.db", "robot.yaml", "false", "slr")[:4]
    ['slr', 'ros', 'bridge', 'robot.db']
    """
    return ["slr", "ros", "bridge", db, "--ros-args",
            "-p", ["map:=", mapping],
            "-p", ["all_topics:=", all_topics],
            "-r", ["__node:=", node_name]]


def generate_launch_description():
    # Imported here so that the command above is usable where `launch` is not installed.
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, ExecuteProcess
    from launch.substitutions import LaunchConfiguration

    return LaunchDescription([
        DeclareLaunchArgument("db", default_value="robot.db",
                              description="the store (a file, or a postgresql:// URL)"),
        DeclareLaunchArgument("map", default_value=str(HERE / "robot.yaml"),
                              description="the MAP file: topics -> events"),
        DeclareLaunchArgument("all_topics", default_value="false",
                              description="also store every unmapped topic"),
        DeclareLaunchArgument("node_name", default_value="slr_bridge"),
        ExecuteProcess(
            cmd=bridge_command(LaunchConfiguration("db"), LaunchConfiguration("map"),
                               LaunchConfiguration("all_topics"),
                               LaunchConfiguration("node_name")),
            output="screen"),
    ])
