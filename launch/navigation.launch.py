"""The whole navigation graph for real sensors: `ros2 launch ins_gnss_ros navigation.launch.py`.

Arguments: ``profile`` (a params file in the package's config/, without .yaml; default
``default``) and ``nodes`` (comma-separated executables to start; default the live graph; append ``live_view``
for the Foxglove live view, docs/VIEWING.md).
Every node respawns after a crash, as ``trial run`` does without ROS launch.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

LIVE_GRAPH = "imu_preprocessor,strapdown,gnss_driver,phase_heading,mag_compass,ekf"


def _nodes(context):
    share = FindPackageShare("ins_gnss_ros").perform(context)
    params = f"{share}/config/{LaunchConfiguration('profile').perform(context)}.yaml"
    names = [n.strip() for n in LaunchConfiguration("nodes").perform(context).split(",") if n.strip()]
    return [Node(package="ins_gnss_ros", executable=name, name=name, parameters=[params],
                 respawn=True, respawn_delay=1.0, output="screen")
            for name in names]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument("profile", default_value="default",
                              description="params file config/<profile>.yaml"),
        DeclareLaunchArgument("nodes", default_value=LIVE_GRAPH,
                              description="comma-separated node executables to start"),
        OpaqueFunction(function=_nodes),
    ])
