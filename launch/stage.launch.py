"""
Launch the flexure_sim stage node.

    ros2 launch flexure_sim stage.launch.py
    ros2 launch flexure_sim stage.launch.py mechanism:=./my_stage.yaml time_mode:=fast
    ros2 launch flexure_sim stage.launch.py namespace:=stage1 record:=false

The parameters file (default: the installed ``config/stage_node.params.yaml``, every parameter
at its default) is read first; the arguments below override it.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

#: (name, default, description) of every launch argument.
ARGUMENTS = (
    ("mechanism", "microstage",
     "built-in mechanism name (microstage, fourbar_cantilever, fourbar_mixed) or path of a "
     "mechanism YAML file"),
    ("time_mode", "realtime", "realtime | fast | lockstep"),
    ("record", "true", "record every run to MCAP (true | false)"),
    ("namespace", "", "namespace of the node and its topics, e.g. stage1"),
    ("params_file", "",
     "parameters file (ros__parameters) read before the other arguments; default: the "
     "installed config/stage_node.params.yaml"),
    ("use_sim_time", "false", "take time from /clock (true | false)"),
)


def generate_launch_description():
    """Declare the arguments and the stage node."""
    installed = PathJoinSubstitution(
        [FindPackageShare("flexure_sim"), "config", "stage_node.params.yaml"])
    declared = []
    for name, default, description in ARGUMENTS:
        value = installed if name == "params_file" else default
        declared.append(DeclareLaunchArgument(name, default_value=value, description=description))
    overrides = {
        "mechanism": LaunchConfiguration("mechanism"),
        "time_mode": LaunchConfiguration("time_mode"),
        "record": ParameterValue(LaunchConfiguration("record"), value_type=bool),
        "use_sim_time": ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool),
    }
    node = Node(
        package="flexure_sim",
        executable="stage_node",
        name="stage_node",
        namespace=LaunchConfiguration("namespace"),
        output="screen",
        emulate_tty=True,
        parameters=[LaunchConfiguration("params_file"), overrides],
    )
    return LaunchDescription([*declared, node])
