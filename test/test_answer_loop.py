"""
`AnswerLoop` (in-process rclpy, real Fast DDS on loopback).

A controller's measurements are taken and answered in the serving thread, the node's services
served beside it; `stop` and a shutdown of the context end it.
"""
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from flexure_sim.node.apps.answer_loop import AnswerLoop
from flexure_sim.node.publish.qos_profiles import command_qos
from flexure_sim.node.stage.polled import PolledGroup

TIMEOUT_S = 20.0


def _until(predicate, what):
    """Wait (up to `TIMEOUT_S`) for ``predicate``; fail naming ``what``."""
    deadline = time.monotonic() + TIMEOUT_S
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.005)


class Answerer:
    """A node answering each Float64 on ``in`` with twice its value on ``out``, as a controller."""

    def __init__(self, context):
        self.node = rclpy.create_node("answer_loop_test", context=context)
        self.out = self.node.create_publisher(Float64, "out", command_qos())
        self.sub = self.node.create_subscription(Float64, "in", self.answer, command_qos(),
                                                 callback_group=PolledGroup())
        self.threads = set()
        self.reset_threads = set()
        self.node.create_service(Trigger, "~/reset", self.on_reset)
        self.loop = AnswerLoop(self.node, [(self.sub, self.answer)])
        self.error = None
        self.thread = threading.Thread(target=self._serve)

    def _serve(self):
        try:
            self.loop.serve()
        except BaseException as exc:  # noqa: BLE001 - the test reports it
            self.error = exc

    def answer(self, msg):
        self.threads.add(threading.get_ident())
        self.out.publish(Float64(data=2.0 * msg.data))

    def on_reset(self, _request, response):
        self.reset_threads.add(threading.get_ident())
        response.success, response.message = True, "reset"
        return response


def test_every_message_is_answered_in_order_in_the_serving_thread_and_services_still_run(
        context):
    answerer = Answerer(context)
    peer = rclpy.create_node("answer_loop_peer", context=context)
    answers = []
    peer.create_subscription(Float64, "out", lambda m: answers.append(m.data), command_qos())
    pub = peer.create_publisher(Float64, "in", command_qos())
    client = peer.create_client(Trigger, "/answer_loop_test/reset")
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(peer)
    answerer.thread.start()
    try:
        _until(lambda: pub.get_subscription_count() == 1
               and answerer.out.get_subscription_count() == 1, "the topics to match")
        sent = [float(k) for k in range(300)]
        for value in sent:  # reliable, keep last 10000 (command_qos): none is overwritten
            pub.publish(Float64(data=value))
        deadline = time.monotonic() + TIMEOUT_S
        while len(answers) < len(sent):
            executor.spin_once(timeout_sec=0.1)
            assert answerer.error is None, answerer.error
            assert time.monotonic() < deadline, f"{len(answers)} of {len(sent)} answered"
        assert answers == [2.0 * v for v in sent]
        # The measurements ran in the serving thread, never in the executor's.
        assert answerer.threads == {answerer.thread.ident}
        # A service of the same node is served meanwhile (by the executor thread).
        assert client.wait_for_service(timeout_sec=TIMEOUT_S)
        future = client.call_async(Trigger.Request())
        executor.spin_until_future_complete(future, timeout_sec=TIMEOUT_S)
        assert future.done() and future.result().success
        assert answerer.reset_threads and answerer.thread.ident not in answerer.reset_threads
    finally:
        answerer.loop.stop()
        answerer.thread.join(TIMEOUT_S)
        executor.shutdown()
    assert not answerer.thread.is_alive(), "stop() did not end serve()"
    assert answerer.error is None, answerer.error


def test_a_shutdown_of_the_context_ends_serve_as_it_ends_rclpy_spin(context):
    answerer = Answerer(context)
    answerer.thread.start()
    assert answerer.loop.serving.wait(TIMEOUT_S)
    rclpy.try_shutdown(context=context)
    answerer.thread.join(TIMEOUT_S)
    assert not answerer.thread.is_alive(), "serve() outlived the context"
    assert isinstance(answerer.error, ExternalShutdownException), answerer.error


def test_serve_on_a_context_already_shut_down_ends_at_once(context):
    answerer = Answerer(context)
    rclpy.try_shutdown(context=context)
    answerer.thread.start()
    answerer.thread.join(TIMEOUT_S)
    assert not answerer.thread.is_alive()
    assert isinstance(answerer.error, ExternalShutdownException), answerer.error
