"""
The launch file and the parameters file, as a ROS 2 user starts the node with them.

The params file is checked against the node's parameter table and used by a real node
(``--params-file``). The launch file is imported and run through ``generate_launch_description``
when the ``launch`` packages are importable (a Jazzy install; not on PyPI), and otherwise parsed:
the test prints which check ran.
"""

import ast
import importlib.util
from pathlib import Path
import sys

import pytest
from rcl_interfaces.srv import GetParameters
import yaml

from flexure_sim.engine.mechanism.loader import builtin_names, load_mechanism
from flexure_sim.node.params.table import parameter_specs

from node_harness import NodeProcess, Peer, next_domain_id

ROOT = Path(__file__).resolve().parents[1]
PARAMS_FILE = ROOT / "config" / "stage_node.params.yaml"
LAUNCH_FILE = ROOT / "launch" / "stage.launch.py"
LAUNCH_ARGUMENTS = {"mechanism", "time_mode", "record", "namespace", "params_file", "use_sim_time"}
DRIVE_PARAMETERS = ("stroke_min", "stroke_max", "slew_rate")


def _stage_drive_defaults():
    drive = load_mechanism("microstage").drive
    return drive.stroke[0], drive.stroke[1], drive.slew_rate


def test_params_file_lists_every_parameter_at_its_default():
    doc = yaml.safe_load(PARAMS_FILE.read_text())
    values = doc["/**"]["ros__parameters"]
    specs = {s.name: s for s in parameter_specs(_stage_drive_defaults())}
    assert set(values) == set(specs) - set(DRIVE_PARAMETERS)
    for name, value in values.items():
        spec = specs[name]
        assert type(value) is spec.type, f"{name}: {value!r} is not a {spec.type.__name__}"
        assert value == spec.default, name
    # The drive's limits default to the mechanism's: shown commented out, with the stage's
    # values, in a form that reads back as numbers when uncommented.
    text = PARAMS_FILE.read_text()
    for name in DRIVE_PARAMETERS:
        line = next(ln for ln in text.splitlines() if ln.strip().startswith(f"# {name}:"))
        value = yaml.safe_load(line.strip()[2:])[name]
        assert isinstance(value, float) and value == specs[name].default, name


def test_params_file_is_not_a_builtin_mechanism():
    assert "stage_node.params" not in builtin_names()


def test_node_takes_its_parameters_from_a_params_file(tmp_path):
    doc = yaml.safe_load(PARAMS_FILE.read_text())
    params = doc["/**"]["ros__parameters"]
    params.update(publish_rate=500.0, time_mode="lockstep", record=False, stroke_max=1.0e-6)
    custom = tmp_path / "my.params.yaml"
    custom.write_text(yaml.safe_dump(doc))
    domain = next_domain_id()
    node = NodeProcess(tmp_path / "node", domain, extra_args=["--ros-args", "--params-file",
                                                              str(custom)])
    peer = Peer(domain)
    try:
        request = GetParameters.Request()
        request.names = ["publish_rate", "time_mode", "record", "stroke_max", "mechanism"]
        response = peer.call(GetParameters, "/stage_node/get_parameters", request)
        got = [v.double_value if v.type == 3 else v.string_value if v.type == 4 else v.bool_value
               for v in response.values]
        assert got == [500.0, "lockstep", False, 1.0e-6, "microstage"]
    finally:
        peer.close()
        assert node.stop() == 0, node.stderr()
    assert node.recordings() == []


def _argument_names_by_parsing(path: Path) -> set:
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "ARGUMENTS" for t in node.targets):
            return {ast.literal_eval(item.elts[0]) for item in node.value.elts}
    raise AssertionError("no ARGUMENTS table in the launch file")


def test_launch_file_declares_its_arguments_and_the_node(capsys):
    names = _argument_names_by_parsing(LAUNCH_FILE)
    assert names == LAUNCH_ARGUMENTS
    find = importlib.util.find_spec
    if find("launch") is None or find("launch_ros") is None:
        with capsys.disabled():
            print("\n[launch file] launch/launch_ros not importable: checked by parsing only")
        source = LAUNCH_FILE.read_text()
        for needed in ('executable="stage_node"', 'package="flexure_sim"',
                       'LaunchConfiguration("params_file")', "stage_node.params.yaml"):
            assert needed in source
        return
    spec = importlib.util.spec_from_file_location("stage_launch", LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    from launch.actions import DeclareLaunchArgument
    from launch_ros.actions import Node
    declared = {a.name for a in description.entities if isinstance(a, DeclareLaunchArgument)}
    nodes = [a for a in description.entities if isinstance(a, Node)]
    with capsys.disabled():
        print("\n[launch file] imported and generate_launch_description() called")
    assert declared == LAUNCH_ARGUMENTS
    assert len(nodes) == 1 and nodes[0].node_package == "flexure_sim"


def test_launch_and_params_files_are_installed_to_the_share_directory():
    share = Path(sys.prefix) / "share" / "flexure_sim"
    if not (share / "package.xml").exists():
        pytest.fail(f"flexure_sim is not installed in {sys.prefix} (scripts/venv.sh installs it)")
    assert (share / "launch" / "stage.launch.py").read_text() == LAUNCH_FILE.read_text()
    assert (share / "config" / "stage_node.params.yaml").read_text() == PARAMS_FILE.read_text()
