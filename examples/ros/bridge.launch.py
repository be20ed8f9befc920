"""Launch the slr bridge with ROS 2's launch system (needs a ROS 2 installation with the
`launch` package; the pip wheels of rclpy do not bring it).

    ros2 launch examples/ros/bridge.launch.py db:=robot.db map:=examples/ros/robot.yaml
    ros2 launch examples/ros/bridge.launch.py db:=robot.db all_topics:=true node_name:=slr

It runs `slr ros bridge DB --ros-args -p map:=MAP -p all_topics:=BOOL -r __node:=NAME`:
the MAP file and `all_topics` as the node's ROS parameters (docs/ros.md, "The live bridge").
"""
from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.substitutions import LaunchConfiguration

HERE = Path(__file__).resolve().parent


def generate_launch_description() -> LaunchDescription:
    db = LaunchConfiguration("db")
    mapping = LaunchConfiguration("map")
    all_topics = LaunchConfiguration("all_topics")
    node_name = LaunchConfiguration("node_name")
    return LaunchDescription([
        DeclareLaunchArgument("db", default_value="robot.db",
                              description="the store (a file, or a postgresql:// URL)"),
        DeclareLaunchArgument("map", default_value=str(HERE / "robot.yaml"),
                              description="the MAP file: topics -> events"),
        DeclareLaunchArgument("all_topics", default_value="false",
                              description="also store every unmapped topic"),
        DeclareLaunchArgument("node_name", default_value="slr_bridge"),
        ExecuteProcess(
            cmd=["slr", "ros", "bridge", db, "--ros-args",
                 "-p", ["map:=", mapping],
                 "-p", ["all_topics:=", all_topics],
                 "-r", ["__node:=", node_name]],
            output="screen"),
    ])
