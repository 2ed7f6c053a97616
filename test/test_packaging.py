"""
Packaging.

package.xml names every dependency setup.py declares (by rosdep key), matplotlib is an optional
extra the node never imports, and the plot tool says what to install without it. Built-in
mechanisms: found in the running code's own install (engine/mechanism/builtins.py).
"""
from __future__ import annotations

import ast
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: rosdep keys of the pip requirements, from rosdistro's rosdep/python.yaml (mcap has no key
#: of its own: the pip key mcap-ros2-support installs it as its dependency).
ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "numba": "python3-numba",
    "PyYAML": "python3-yaml",
    "mcap": "mcap-ros2-support",
    "mcap-ros2-support": "mcap-ros2-support",
    "matplotlib": "python3-matplotlib",
    "pytest": "python3-pytest",
    "rosbags": "python3-rosbags-pip",
}


def setup_keywords() -> dict:
    """Return the literal keyword arguments of the setup() call in setup.py."""
    tree = ast.parse((ROOT / "setup.py").read_text())
    call = next(node for node in ast.walk(tree) if isinstance(node, ast.Call)
                and getattr(node.func, "id", None) == "setup")
    out = {}
    for kw in call.keywords:
        try:
            out[kw.arg] = ast.literal_eval(kw.value)
        except ValueError:
            pass
    return out


def package_xml_depends() -> dict[str, set[str]]:
    root = ET.parse(ROOT / "package.xml").getroot()
    out: dict[str, set[str]] = {}
    for el in root:
        out.setdefault(el.tag, set()).add((el.text or "").strip())
    return out


def _name(requirement: str) -> str:
    """Return the distribution name of a requirement such as ``numpy>=1.26``."""
    return re.split(r"[<>=!~ ;\[]", requirement, maxsplit=1)[0]


def test_setup_and_requirements_state_the_same_minimum_versions():
    setup = setup_keywords()
    declared = setup["install_requires"] + [r for extra in setup["extras_require"].values()
                                            for r in extra]
    lines = [line.split("#")[0].strip() for line in
             (ROOT / "requirements.txt").read_text().splitlines()]
    required = {_name(line): line for line in lines if line}
    for req in declared:
        assert re.search(r">=\d", req), f"setup.py: {req} states no minimum version"
        assert required.get(_name(req)) == req, (
            f"setup.py says {req}, requirements.txt {required.get(_name(req), 'nothing')}")


def test_package_xml_names_every_python_dependency_by_its_rosdep_key():
    setup = setup_keywords()
    deps = package_xml_depends()
    run = set(deps.get("exec_depend", set())) | deps.get("depend", set())
    test = deps.get("test_depend", set()) | deps.get("depend", set())
    wanted = [(r, run) for r in setup["install_requires"] + setup["extras_require"]["plot"]]
    wanted += [(r, test) for r in setup["extras_require"]["test"]]
    wanted = [(_name(r), have) for r, have in wanted]
    missing = [f"{req} ({ROSDEP_KEYS.get(req, 'no key known: add it to ROSDEP_KEYS')})"
               for req, have in wanted if ROSDEP_KEYS.get(req) not in have]
    assert not missing, f"package.xml lacks: {', '.join(missing)}"
    assert "matplotlib" not in map(_name, setup["install_requires"]), (
        "matplotlib is the extra 'plot'")
    # colcon runs pytest (not unittest, which finds nothing) when pytest is a test dependency.
    assert "pytest" in map(_name, setup["extras_require"]["test"])


def test_the_node_does_not_import_matplotlib():
    probe = ("import sys; import flexure_sim.node.stage.stage_node, flexure_sim.cli; "
             "print(sorted(m for m in sys.modules if m.split('.')[0] == 'matplotlib'))")
    p = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120,
                       cwd=ROOT, check=True)
    assert p.stdout.strip() == "[]"


def test_plot_without_matplotlib_names_the_missing_extra(tmp_path):
    from tools_fixtures import record_stage_run

    run = tmp_path / "run.mcap"
    record_stage_run(run, levels=(1.0e-6,), rest=0.002, dwell=0.005)
    hide = ("import sys; sys.modules['matplotlib'] = None; from flexure_sim.cli import main; "
            f"sys.exit(main(['plot', {str(run)!r}, '-o', {str(tmp_path / 'plots')!r}]))")
    p = subprocess.run([sys.executable, "-c", hide], capture_output=True, text=True, timeout=120,
                       cwd=ROOT)
    assert p.returncode == 1 and "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "matplotlib" in lines[0] and "extra 'plot'" in lines[0], p.stderr
    assert not (tmp_path / "plots").exists()


def test_builtins_come_from_the_install_the_code_belongs_to(tmp_path):
    """
    Layouts built by hand.

    An installed copy reads <prefix>/share, a checkout its config/, code in neither layout finds
    nothing of its own (then only the ament index can answer).
    """
    from flexure_sim.engine.mechanism import builtins

    prefix = tmp_path / "prefix"
    installed = prefix / "lib" / "python3.11" / "site-packages" / "flexure_sim"
    debian = tmp_path / "usr" / "lib" / "python3" / "dist-packages" / "flexure_sim"
    share = prefix / "share" / "flexure_sim" / "config"
    for folder in (installed, debian, share):
        folder.mkdir(parents=True)
    assert builtins.install_prefix(installed) == prefix
    assert builtins.install_prefix(debian) == tmp_path / "usr"
    assert builtins.own_data_dir(installed) == share
    checkout = tmp_path / "checkout"
    (checkout / "flexure_sim").mkdir(parents=True)
    (checkout / "config").mkdir()
    assert builtins.own_data_dir(checkout / "flexure_sim") is None, "no package.xml: not ours"
    (checkout / "package.xml").write_text("<package/>")
    assert builtins.own_data_dir(checkout / "flexure_sim") == checkout / "config"
    assert builtins.install_prefix(checkout / "flexure_sim") is None
    # This test runs the source tree: its built-ins are the checkout's.
    assert builtins.builtin_dir() == ROOT / "config"
    assert builtins.find_builtin("microstage") == ROOT / "config" / "microstage.yaml"
    assert builtins.find_builtin("no_such_mechanism") is None


def test_sweep_without_dask_names_the_missing_extra(tmp_path):
    hide = ("import sys; sys.modules['distributed'] = None; from flexure_sim.cli import main; "
            f"sys.exit(main(['sweep', 'config/studies/stage_notch_grid.yaml', '-o', "
            f"{str(tmp_path / 'r.parquet')!r}]))")
    p = subprocess.run([sys.executable, "-c", hide], capture_output=True, text=True, timeout=120,
                       cwd=ROOT)
    assert p.returncode == 1 and "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "distributed" in lines[0] and "extra 'sweep'" in lines[0], p.stderr
