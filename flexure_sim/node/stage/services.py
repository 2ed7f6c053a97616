"""
The stage node's services and the recording they start and stop (a mixin of ``shell.StageNode``).

``~/reset``, ``~/record`` and ``~/step`` (docs/node.md, Services): each runs its work on the
stepping thread through the request queue (`requests`), which owns the simulation and the
recording. It uses the node's ``loop``, ``session``, ``interface``, ``mechanism``,
``mechanism_path``, ``spatial``, ``_values``, ``_log``, ``_tick_names``, ``_diag_topic``,
``_command_subs``, ``_display_topics`` and ``_sync_record_param``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from rclpy.parameter import Parameter
from std_srvs.srv import SetBool, Trigger

from flexure_sim.node.inputs.command_intake import REJECTED_SUFFIX
from flexure_sim.node.publish.cdr import REJECTED_TYPE
from flexure_sim.node.publish.qos_profiles import command_qos, stream_qos
from flexure_sim.node.record.session import run_metadata
from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL


class StageServices:
    """The stage node's service callbacks and recording control (module docstring)."""

    loop: Any
    session: Any

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = self.loop.requests.run(self._reset)
        return response

    def _on_record(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        ok, message = self._set_recording(bool(request.data))
        if ok:
            self._sync_record_param = True
            try:
                self.set_parameters([Parameter("record", Parameter.Type.BOOL, bool(request.data))])
            finally:
                self._sync_record_param = False
        response.success, response.message = ok, message
        return response

    def _on_step(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self.time_mode != "lockstep":
            response.success = False
            response.message = ("~/step works in lockstep mode only "
                                f"(time_mode is {self.time_mode})")
            return response
        response.success, response.message = self.loop.requests.run(self.loop.step_once)
        return response

    def _set_recording(self, on: bool) -> tuple[bool, str]:
        def change() -> tuple[bool, str]:
            current = self.session.current
            if on:
                if current is not None:
                    return True, f"already recording to {current.path}"
                return True, f"recording to {self._start_recording()}"
            if current is None:
                return True, "not recording"
            return True, f"closed {self.session.stop()}"
        return self.loop.requests.run(change)

    # ======================================================= stepping-thread work
    def _start_recording(self) -> Path:
        values = self._values()
        qos = stream_qos()
        topics = [(name, spec.type_name, qos)
                  for name, spec in zip(self._tick_names, self.interface.tick_topics)]
        topics.append((self._diag_topic, self.interface.diagnostics.type_name, qos))
        commands = command_qos(values["command_reliability"], values["command_depth"])
        for sub, spec in zip(self._command_subs, self.interface.commands):
            topics.append((sub.topic_name, spec.type_name, commands))
        topics += self._display_topics
        topics += [(sub.topic_name + REJECTED_SUFFIX, REJECTED_TYPE, commands)
                   for sub in self._command_subs]
        loop = self.loop
        node = self.get_fully_qualified_name()
        metadata = run_metadata(values, self.mechanism, self.mechanism_path, self.interface, node,
                                loop.n_steps, RELINEARIZE_TOL, loop.runs, loop.sim.state.t)
        metadata["space"] = "3d" if self.spatial else "2d"  # the engine that ran
        return self.session.start(values, self.mechanism.name, node, topics, metadata,
                                  lossless=self.time_mode != "realtime")

    def _reset(self) -> tuple[bool, str]:
        closed = self.session.stop()
        self.loop.reset()
        message = "simulation reset to t = 0"
        if closed is not None:
            message += f"; closed {closed}"
            if self.get_parameter("record").value:
                message += f"; recording to {self._start_recording()}"
        self._log.info(message)
        return True, message
