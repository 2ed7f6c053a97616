"""
Registry of the ``flexure-sim`` subcommands that live in the tools package.

Each module (named relative to the flexure_sim package) defines ``register(subparsers)``, which
adds its subparser and sets ``handler=<function(args) -> exit code>`` with ``set_defaults``. Add
one line per module.
"""

from __future__ import annotations

import importlib

#: Tool modules, in the order their commands appear in ``flexure-sim --help``.
TOOL_MODULES: tuple[str, ...] = (
    "tools.design.fit",
    "tools.run.run_info",
    "tools.run.analyse",
    "tools.run.plot",
    "tools.run.export",
    "node.apps.replay",
    "tools.design.linear_commands",
    "tools.design.sensitivity_command",
    "tools.bench.benchmarks",
    "tools.design.sweep",
    "tools.design.optimize_command",
    "tools.design.piezo_loop",
    "tools.design.hinge",
)


def register(subparsers) -> None:
    """Add every tool's subcommand to the ``flexure-sim`` parser."""
    for name in TOOL_MODULES:
        importlib.import_module(f"flexure_sim.{name}").register(subparsers)
