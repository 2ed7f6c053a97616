"""
The stage node's parameters while it runs: validation as a whole, and changes handed over.

`LiveParameters` is the part of ``shell.StageNode`` behind its three parameter callbacks: the
pre-set one turns ``ros2 param set`` integers and strings into the declared doubles
(``table.as_declared_type``), the on-set one checks the resulting set of values as a whole
(``checks.validate``, per drive ``drive_bank.drives_problem``, and whether the engine could
hold the changed stroke ends, ``engine_guard.StrokeProbe``), the post-set one hands accepted
changes to the stepping thread through its request queue, notes them in the recording, and
returns once the stepping thread has taken them: a command sent after ``set_parameters``
answered meets the new limits (the queue is served between ticks, so an answer waits up to one
period).
It uses the node's ``_specs``, ``_named``, ``_probe``, ``mechanism``, ``loop``, ``session``
and ``_set_recording``.
"""
from __future__ import annotations

from typing import Any, Optional

from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter

from flexure_sim.node.inputs.command_checks import DriveLimits
from flexure_sim.node.inputs.drive_bank import (
    LIMIT_KEYS, drive_limits, drives_problem, parameter_name, stroke_ends,
)
from flexure_sim.node.params.checks import validate
from flexure_sim.node.params.table import as_declared_type
from flexure_sim.node.publish.display import display_every
from flexure_sim.node.publish.interface import value_text
from flexure_sim.node.record.session import PARAMETER_CHANGE_NAME


class LiveParameters:
    """The stage node's parameter callbacks (module docstring); a mixin of ``StageNode``."""

    def _values(self) -> dict[str, Any]:
        return {name: self.get_parameter(name).value for name in self._specs}

    @staticmethod
    def _limits(values: dict[str, Any]) -> DriveLimits:
        return DriveLimits(float(values["stroke_min"]), float(values["stroke_max"]),
                           float(values["slew_rate"]))

    def _problem(self, values: dict[str, Any], current: dict[str, Any]) -> Optional[str]:
        """
        Why ``values`` are invalid, or None.

        Checked as a whole, per drive, and whether the engine could follow the (changed) stroke
        ends.
        """
        problem = validate(values) or drives_problem(values, [d.name for d in self._named])
        if problem:
            return problem
        for name, drive, unit in stroke_ends(self.mechanism):
            if values[name] != current[name]:
                problem = self._probe.end_problem(name, values[name], drive, unit)
                if problem:
                    return problem
        return None

    def _coerce_parameters(self, params: list[Parameter]) -> list[Parameter]:
        """Pre-set callback: ``ros2 param set ... 1e-6`` or ``2`` sets a double parameter."""
        out = []
        for p in params:
            value = as_declared_type(self._specs.get(p.name), p.value)
            out.append(p if value is p.value else Parameter(p.name, Parameter.Type.DOUBLE, value))
        return out

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """On-set callback: check the whole resulting set of values; no side effects."""
        current = self._values()
        values = dict(current)
        for p in params:
            if p.name in values:
                values[p.name] = p.value
        problem = self._problem(values, current)
        return SetParametersResult(successful=problem is None, reason=problem or "")

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """
        Post-set callback: hand accepted changes to the stepping thread; wait until it took them.

        Without the wait the service answered before the change reached the stepping thread,
        so a command sent right after a successful ``stroke_max`` change could still be
        clamped to the old stroke (``test_node_engine_guard``).
        """
        names = {p.name for p in params}
        values = self._values()
        loop = self.loop
        calls = []
        if names & {"stroke_min", "stroke_max", "slew_rate"} and not self._named \
                and loop.filter is not None:
            limits = self._limits(values)
            calls.append(loop.requests.call(lambda: loop.filter.set_limits(limits)))
        for d in self._named:
            if names & {parameter_name(d.name, k) for k in LIMIT_KEYS}:
                one, limits = loop.filter.filter(d.name), drive_limits(values, d.name)
                calls.append(loop.requests.call(
                    lambda one=one, limits=limits: one.set_limits(limits)))
        if names & {"publish_rate", "wake_spin", "monitor_rate", "merge_late_ticks"}:
            rate, spin = float(values["publish_rate"]), float(values["wake_spin"])
            monitor, merge = float(values["monitor_rate"]), int(values["merge_late_ticks"])
            calls.append(loop.requests.call(
                lambda: loop.set_pacing(rate, spin, monitor, merge)))
        if names & {"publish_rate", "display_rate"}:
            every = display_every(float(values["publish_rate"]), float(values["display_rate"]))
            calls.append(loop.requests.call(lambda: setattr(loop, "display_every", every)))
        if "display_scale" in names:
            scale = float(values["display_scale"])
            calls.append(loop.requests.call(
                lambda: setattr(loop.display.display.scene, "display_scale", scale)))
        if "record" in names and not self._sync_record_param:
            ok, message = self._set_recording(bool(values["record"]))
            (self._log.info if ok else self._log.error)(message)
        changed = {p.name: value_text(p.value) for p in params}
        calls.append(loop.requests.call(lambda: self.session.note(
            PARAMETER_CHANGE_NAME, {"t": repr(loop.sim.state.t), **changed})))
        for future in calls:
            ok, message = loop.requests.wait(future)
            if not ok:
                self._log.error(f"applying {', '.join(sorted(names))}: {message}")
