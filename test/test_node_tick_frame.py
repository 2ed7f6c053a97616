"""
The stepping loop's tick frame (node/publish/tick_frame.py): `StageInterface.encode`, to the byte.

``encode`` packs each message from a Snapshot and is itself proven equal to rclpy's
serialize_message (test_node_interface.py); the tick frame packs every message of a tick from
the engine's tick report into the recorder's batch frame in one compiled call. Compared along
runs of every kind of mechanism, in the modes with and without /clock, with every topic and
with the control topics only (``monitor_rate``), with and without a sensor reading.
"""
from __future__ import annotations

import pytest

from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.solver.tick_report import TickReport
from flexure_sim.node.publish.interface import StageInterface
from flexure_sim.node.publish.tick_frame import TickFrame
from flexure_sim.node.record.process import FRAME_ITEM, FRAME_STAMP
from test_tick_report import MECHANISMS, commands

#: ROS 2's message packages (the interface's types), though no rclpy import shows it here.
pytestmark = pytest.mark.ros


@pytest.mark.parametrize("mode", ["realtime", "lockstep"])
@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_packed_ticks_are_the_encoded_messages_and_the_recorders_frame(name, mode):
    mech = MECHANISMS[name]()
    sim = Simulation(mech, energy=False)
    interface = StageInterface(mech, mode, "left/")
    report = TickReport(sim.model)
    frame = TickFrame(interface, report.index)
    for k in range(12):
        if sim.model.drives:
            sim.set_command(commands(sim.model, k))
        sim.step(2)
        values = report.fill_data(sim.data)
        snap = sim.snapshot()
        stamp = round(snap.t * 1e9) + 1_700_000_000 * 10**9  # a wall-clock-sized stamp
        measured = 1.25e-6 - 3e-9 * k
        for monitor in (True, False):
            expected = interface.encode(snap, stamp, measured, monitor)
            body, layout = frame.pack(values, measured, stamp, monitor)
            assert [body[a:b] for a, b in layout.spans] == expected, (name, mode, k, monitor)
            channels = (range(len(interface.tick_topics)) if monitor
                        else interface.control_indices)
            assert layout.channels == list(channels)
            # What ProcessRecording.write_batch sends for the same messages.
            parts = [FRAME_STAMP.pack(stamp)]
            for channel, data in zip(channels, expected):
                parts += [FRAME_ITEM.pack(channel, len(data)), data]
            assert body == b"".join(parts)
