"""ROS 2 actions over Zenoh, both ways, against zenoh-ros2-sdk.

zenoh-ros2-sdk 0.1.8 has no action client or server, so the ROS 2 side is built from its
service and topic primitives exactly as rcl_action composes an action: the services
``send_goal``, ``get_result`` and ``cancel_goal``, the topics ``feedback`` and ``status``. The
type hashes are the values Jazzy's rosidl generates (written here, not computed by simbridge):
a wrong hash in simbridge's key expressions would be silence, and these tests would time out.
"""

from __future__ import annotations

import asyncio
import threading
import time
import uuid
from collections.abc import AsyncIterator
from typing import Any

import numpy as np
import pytest
from websockets.asyncio.client import connect

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from simbridge.ros2.typehash import TypeHasher
from tests.helpers import recv_until, send_json, wait_for, ws_url
from tests.ros2.zenoh.conftest import Router, eventually, zenoh_options


pytestmark = pytest.mark.e2e

FIB = "example_interfaces/action/Fibonacci"
#: RIHS01 of the rcl_action types of example_interfaces/action/Fibonacci (ROS 2 Jazzy).
HASHES = {
    "send_goal": "RIHS01_d1a57fb2a4afe8c21e34fb10db206f16ce6729b28531141472df92277c55b557",
    "get_result": "RIHS01_1b0de0d5d29dc955d92f546706568428632771db13ec84c15ec1c1a59f424a57",
    "feedback": "RIHS01_c1de71afd52e49a89c53d8262366884185bc0a02f78ce051c4e46b0a7fe59bb2",
    "cancel_goal": "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a",
    "status": "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
}
TYPES = {
    "send_goal": f"{FIB}_SendGoal",
    "get_result": f"{FIB}_GetResult",
    "feedback": f"{FIB}_FeedbackMessage",
    "cancel_goal": "action_msgs/srv/CancelGoal",
    "status": "action_msgs/msg/GoalStatusArray",
}


def kw(router: Router) -> dict[str, Any]:
    return {"router_ip": "127.0.0.1", "router_port": router.port}


@pytest.fixture
async def demo(router: Router, ros2: Any) -> AsyncIterator[App]:
    """A simbridge with the tutorial nodes (its /fibonacci action) on the router's network."""
    settings = ServerSettings(host="127.0.0.1", port=0, http_port=0, demo_nodes=True)
    app = App(settings, zenoh=zenoh_options(router))
    await app.start()
    yield app
    await app.stop()


def test_simbridge_hashes_the_action_types_as_rosidl_does(zapp_registry: Any) -> None:
    hasher = TypeHasher(zapp_registry, "jazzy")
    send_goal, get_result, feedback = zapp_registry.action_wire(FIB)
    assert hasher.service(send_goal) == HASHES["send_goal"]
    assert hasher.service(get_result) == HASHES["get_result"]
    assert hasher.message(feedback) == HASHES["feedback"]
    assert hasher.service("action_msgs/srv/CancelGoal") == HASHES["cancel_goal"]
    assert hasher.message("action_msgs/msg/GoalStatusArray") == HASHES["status"]


@pytest.fixture
def zapp_registry() -> Any:
    from simbridge.msgs import TypeRegistry

    return TypeRegistry()


def _uuid(raw: bytes) -> Any:
    from zenoh_ros2_sdk import get_message_class

    cls = get_message_class("unique_identifier_msgs/msg/UUID")
    assert cls is not None
    return cls(uuid=np.frombuffer(raw, dtype=np.uint8).copy())


async def _client(router: Router, action: str, part: str) -> Any:
    from zenoh_ros2_sdk import ROS2ServiceClient

    return await asyncio.to_thread(
        ROS2ServiceClient,
        f"{action}/_action/{part}",
        TYPES[part],
        type_hash=HASHES[part],
        timeout=30.0,
        **kw(router),
    )


async def test_ros2_client_runs_a_goal_of_simbridge_fibonacci_with_feedback_and_result(
    demo: App, router: Router
) -> None:
    from zenoh_ros2_sdk import ROS2Subscriber, get_message_class, get_service_names_and_types

    services = await eventually(
        lambda: (
            (s := dict(get_service_names_and_types(**kw(router))))
            and "/fibonacci/_action/get_result" in s
            and s
        )
    )
    assert services["/fibonacci/_action/send_goal"] == [TYPES["send_goal"]]
    assert services["/fibonacci/_action/cancel_goal"] == [TYPES["cancel_goal"]]
    feedback: list[Any] = []
    statuses: list[Any] = []
    subs = [
        await asyncio.to_thread(
            ROS2Subscriber,
            f"/fibonacci/_action/{part}",
            TYPES[part],
            callback=got.append,
            type_hash=HASHES[part],
            **kw(router),
        )
        for part, got in (("feedback", feedback), ("status", statuses))
    ]
    send_goal = await _client(router, "/fibonacci", "send_goal")
    get_result = await _client(router, "/fibonacci", "get_result")
    goal_class = get_message_class(f"{FIB}_Goal")
    assert goal_class is not None
    goal_id = uuid.uuid4().bytes
    try:
        await asyncio.sleep(0.5)  # the feedback subscriber is matched before the goal starts
        accepted = await asyncio.to_thread(
            send_goal.call, goal_id=_uuid(goal_id), goal=goal_class(order=3)
        )
        assert accepted is not None and accepted.accepted
        assert accepted.stamp.sec > 0
        # rcl_action's client asks for the result at once; the reply comes when the goal ends
        result = await asyncio.to_thread(get_result.call, goal_id=_uuid(goal_id))
        assert result is not None
        assert result.status == 4  # SUCCEEDED
        assert list(result.result.sequence) == [0, 1, 1, 2]
        ours = [f for f in feedback if bytes(f.goal_id.uuid) == goal_id]
        assert ours and list(ours[-1].feedback.sequence)[:2] == [0, 1]
        await wait_for(
            lambda: any(
                s.goal_info.goal_id.uuid.tobytes() == goal_id and s.status == 4
                for msg in statuses
                for s in msg.status_list
            ),
            timeout=5,
        )
        # a goal id nobody sent: status UNKNOWN at once, as rcl_action answers
        unknown = await asyncio.to_thread(get_result.call, goal_id=_uuid(bytes(16)))
        assert unknown is not None and unknown.status == 0
    finally:
        for closable in [*subs, send_goal, get_result]:
            closable.close()


async def test_ros2_client_cancels_a_goal_of_simbridge(demo: App, router: Router) -> None:
    from zenoh_ros2_sdk import get_message_class, get_service_names_and_types

    await eventually(
        lambda: "/fibonacci/_action/cancel_goal" in dict(get_service_names_and_types(**kw(router)))
    )
    send_goal = await _client(router, "/fibonacci", "send_goal")
    get_result = await _client(router, "/fibonacci", "get_result")
    cancel = await _client(router, "/fibonacci", "cancel_goal")
    goal_class = get_message_class(f"{FIB}_Goal")
    info_class = get_message_class("action_msgs/msg/GoalInfo")
    time_class = get_message_class("builtin_interfaces/msg/Time")
    assert goal_class is not None and info_class is not None and time_class is not None
    goal_id = uuid.uuid4().bytes
    try:
        accepted = await asyncio.to_thread(
            send_goal.call, goal_id=_uuid(goal_id), goal=goal_class(order=20)
        )
        assert accepted is not None and accepted.accepted
        reply = await asyncio.to_thread(
            cancel.call,
            goal_info=info_class(goal_id=_uuid(goal_id), stamp=time_class(sec=0, nanosec=0)),
        )
        assert reply is not None and reply.return_code == 0
        assert [bytes(g.goal_id.uuid) for g in reply.goals_canceling] == [goal_id]
        result = await asyncio.to_thread(get_result.call, goal_id=_uuid(goal_id))
        assert result is not None and result.status == 5  # CANCELED
        assert list(result.result.sequence)[:2] == [0, 1]  # the sequence so far
    finally:
        for closable in (send_goal, get_result, cancel):
            closable.close()


class Ros2FibonacciServer:
    """An rmw_zenoh action server of example_interfaces/action/Fibonacci, from SDK primitives.

    Every goal is accepted; it publishes one feedback per number, 0.1 s apart, and succeeds
    with the sequence, unless cancelled (status 5 with the sequence so far).
    """

    def __init__(self, router: Router, name: str) -> None:
        from zenoh_ros2_sdk import ROS2Publisher, ROS2ServiceServer, get_message_class

        common = {"node_name": "ros2_fibonacci_server", **kw(router)}
        self.name = name
        self.goals: dict[bytes, dict[str, Any]] = {}
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.feedback = ROS2Publisher(
            f"{name}/_action/feedback", TYPES["feedback"], type_hash=HASHES["feedback"], **common
        )
        self.classes = {
            n: get_message_class(n)
            for n in (
                f"{FIB}_Feedback",
                f"{FIB}_Result",
                "builtin_interfaces/msg/Time",
                "action_msgs/msg/GoalInfo",
            )
        }
        self.servers = [
            ROS2ServiceServer(
                f"{name}/_action/send_goal",
                TYPES["send_goal"],
                callback=self._send_goal,
                type_hash=HASHES["send_goal"],
                **common,
            ),
            ROS2ServiceServer(
                f"{name}/_action/cancel_goal",
                TYPES["cancel_goal"],
                callback=self._cancel,
                type_hash=HASHES["cancel_goal"],
                **common,
            ),
        ]
        self.results = ROS2ServiceServer(
            f"{name}/_action/get_result",
            TYPES["get_result"],
            type_hash=HASHES["get_result"],
            mode="queue",
            **common,
        )
        self.threads = [threading.Thread(target=self._answer_results, daemon=True)]
        self.threads[0].start()

    def _send_goal(self, request: Any) -> Any:
        goal_id = bytes(request.goal_id.uuid)
        state = {"order": int(request.goal.order), "sequence": [], "status": 2, "uuid": request}
        with self.lock:
            self.goals[goal_id] = state
        thread = threading.Thread(target=self._run, args=(goal_id,), daemon=True)
        self.threads.append(thread)
        thread.start()
        now = time.time()
        stamp = self.classes["builtin_interfaces/msg/Time"](sec=int(now), nanosec=0)  # type: ignore[misc]
        return self.servers[0].response_msg_class(accepted=True, stamp=stamp)

    def _run(self, goal_id: bytes) -> None:
        state = self.goals[goal_id]
        sequence = state["sequence"]
        while not self.stop.is_set():
            with self.lock:
                if state["status"] != 2:
                    return
                if len(sequence) >= state["order"] + 1:
                    state["status"] = 4
                    return
                sequence.append(
                    sequence[-1] + sequence[-2] if len(sequence) >= 2 else len(sequence)
                )
            fb = self.classes[f"{FIB}_Feedback"](sequence=np.array(sequence, dtype=np.int32))  # type: ignore[misc]
            self.feedback.publish(goal_id=_uuid(goal_id), feedback=fb)
            time.sleep(0.1)

    def _cancel(self, request: Any) -> Any:
        goal_id = bytes(request.goal_info.goal_id.uuid)
        canceling = []
        with self.lock:
            state = self.goals.get(goal_id)
            if state is not None and state["status"] == 2:
                state["status"] = 5
                canceling.append(request.goal_info)
        return self.servers[1].response_msg_class(
            return_code=0 if canceling else 2, goals_canceling=canceling
        )

    def _answer_results(self) -> None:
        waiting: list[tuple[Any, bytes]] = []
        while not self.stop.is_set():
            try:
                key, request = self.results.take_request(timeout=0.05)
                waiting.append((key, bytes(request.goal_id.uuid)))
            except Exception:  # nothing came within the timeout
                pass
            for item in list(waiting):
                key, goal_id = item
                with self.lock:
                    state = self.goals.get(goal_id)
                    if state is None or state["status"] == 2:
                        continue
                    seq = np.array(state["sequence"], dtype=np.int32)
                    status = state["status"]
                result = self.classes[f"{FIB}_Result"](sequence=seq)  # type: ignore[misc]
                self.results.send_response(
                    key, self.results.response_msg_class(status=status, result=result)
                )
                waiting.remove(item)

    def close(self) -> None:
        self.stop.set()
        for thread in self.threads:
            thread.join(timeout=5)
        for closable in [*self.servers, self.results, self.feedback]:
            closable.close()


async def test_rosbridge_client_runs_and_cancels_goals_of_a_ros2_action_server(
    zapp: App, router: Router
) -> None:
    server = await asyncio.to_thread(Ros2FibonacciServer, router, "/ros2_fibonacci")
    try:
        async with connect(ws_url(zapp)) as ws:
            # rosapi lists it with its type, as any action server
            async def listed() -> bool:
                await send_json(
                    ws, {"op": "call_service", "service": "/rosapi/action_servers", "id": "a"}
                )
                reply = await recv_until(ws, lambda m: m.get("id") == "a")
                return "/ros2_fibonacci" in reply["values"]["action_servers"]

            deadline = time.monotonic() + 10
            while not await listed():
                assert time.monotonic() < deadline, "the ROS 2 action never reached rosapi"
                await asyncio.sleep(0.2)
            await send_json(
                ws,
                {
                    "op": "call_service",
                    "service": "/rosapi/action_type",
                    "id": "t",
                    "args": {"action": "/ros2_fibonacci"},
                },
            )
            reply = await recv_until(ws, lambda m: m.get("id") == "t")
            assert reply["values"]["type"] == FIB

            # a goal runs to its end: feedback, then the result with status 4
            await send_json(
                ws,
                {
                    "op": "send_action_goal",
                    "id": "g1",
                    "action": "/ros2_fibonacci",
                    "action_type": FIB,
                    "args": {"order": 4},
                    "feedback": True,
                },
            )
            feedback = await recv_until(
                ws, lambda m: m.get("op") == "action_feedback" and m.get("id") == "g1", timeout=10
            )
            assert feedback["values"]["sequence"][:1] == [0]
            result = await recv_until(
                ws, lambda m: m.get("op") == "action_result" and m.get("id") == "g1", timeout=10
            )
            assert result["result"] is True and result["status"] == 4
            assert result["values"]["sequence"] == [0, 1, 1, 2, 3]

            # a long goal cancelled: status 5 with the sequence so far
            await send_json(
                ws,
                {
                    "op": "send_action_goal",
                    "id": "g2",
                    "action": "/ros2_fibonacci",
                    "action_type": FIB,
                    "args": {"order": 40},
                    "feedback": True,
                },
            )
            await recv_until(
                ws, lambda m: m.get("op") == "action_feedback" and m.get("id") == "g2", timeout=10
            )
            await send_json(
                ws, {"op": "cancel_action_goal", "id": "g2", "action": "/ros2_fibonacci"}
            )
            result = await recv_until(
                ws, lambda m: m.get("op") == "action_result" and m.get("id") == "g2", timeout=10
            )
            assert result["status"] == 5
            assert 1 <= len(result["values"]["sequence"]) < 41
    finally:
        await asyncio.to_thread(server.close)
    # the server's tokens are gone: the action leaves the graph
    await wait_for(lambda: "/ros2_fibonacci" not in zapp.graph.actions.actions, timeout=10)


async def test_roslibpy_action_client_runs_and_cancels_goals_of_a_ros2_action_server(
    zapp: App, router: Router, run_roslibpy: Any
) -> None:
    server = await asyncio.to_thread(Ros2FibonacciServer, router, "/ros2_fib_py")
    try:
        result = await run_roslibpy(
            ws_url(zapp),
            "action_goals",
            {
                "action": "/ros2_fib_py",
                "type": FIB,
                "goal": {"order": 3},
                "long_goal": {"order": 40},
            },
            timeout=30,
        )
    finally:
        await asyncio.to_thread(server.close)
    done = result["succeeded"]
    assert done["ok"] and done["status"] == 4
    assert done["values"]["sequence"] == [0, 1, 1, 2]
    assert done["feedback"] and done["feedback"][0]["sequence"][:1] == [0]
    canceled = result["canceled"]
    assert canceled["status"] == 5 and canceled["feedback"]


async def test_a_goal_that_is_not_cdr_gets_an_error_reply_and_the_action_goes_on(
    demo: App, router: Router, ros2: Any
) -> None:
    from zenoh_ros2_sdk import get_message_class, get_service_names_and_types

    from simbridge.ros2.zenoh.attachment import Attachment

    await eventually(
        lambda: "/fibonacci/_action/send_goal" in dict(get_service_names_and_types(**kw(router)))
    )
    key = (
        "0/fibonacci/_action/send_goal/example_interfaces::action::dds_::Fibonacci_SendGoal_/"
        + HASHES["send_goal"]
    )
    attachment = Attachment(1, time.time_ns(), bytes(16)).pack()

    def ask(payload: bytes) -> list[str]:
        errors = []
        for reply in ros2.session.get(key, payload=payload, attachment=attachment, timeout=5):
            if reply.err is not None:
                errors.append(bytes(reply.err.payload.to_bytes()).decode())
        return errors

    for garbage in (b"", b"\x00\x01\x00\x00\x01", b"\x00\x01\x00\x00" + b"\xff" * 3):
        errors = await asyncio.to_thread(ask, garbage)
        assert errors and "not CDR of" in errors[0] and "Fibonacci_SendGoal_Request" in errors[0]
    assert demo.zenoh is not None and demo.zenoh.stats["bad_payloads"] >= 3
    # the action still takes well-formed goals
    send_goal = await _client(router, "/fibonacci", "send_goal")
    goal_class = get_message_class(f"{FIB}_Goal")
    assert goal_class is not None
    try:
        accepted = await asyncio.to_thread(
            send_goal.call, goal_id=_uuid(uuid.uuid4().bytes), goal=goal_class(order=1)
        )
    finally:
        send_goal.close()
    assert accepted is not None and accepted.accepted


async def test_a_ros2_goal_to_an_action_a_client_serves_is_counted_and_times_out(
    router: Router, ros2: Any
) -> None:
    """Issue 29's goal budget for ROS 2 peers: their goals are counted and time out.

    A goal of a ROS 2 client to an action a rosbridge client serves and never answers counts
    against the ROS 2 peers' ``max_pending_goals`` (the bridge's own count: past it a goal is
    not accepted) and is aborted after ``max_goal_timeout`` (its server told
    ``cancel_action_goal``); it used to be held for ever, uncounted.
    """
    from zenoh_ros2_sdk import get_message_class, get_service_names_and_types

    settings = ServerSettings(
        host="127.0.0.1", port=0, http_port=0, max_goal_timeout=2.0, max_pending_goals=1
    )
    app = App(settings, zenoh=zenoh_options(router))
    await app.start()
    link = app.zenoh
    assert link is not None
    try:
        async with connect(ws_url(app)) as server:
            await send_json(server, {"op": "advertise_action", "action": "/slow", "type": FIB})
            await eventually(
                lambda: (
                    "/slow/_action/get_result" in dict(get_service_names_and_types(**kw(router)))
                )
            )
            send_goal = await _client(router, "/slow", "send_goal")
            get_result = await _client(router, "/slow", "get_result")
            goal_class = get_message_class(f"{FIB}_Goal")
            assert goal_class is not None
            goal_id = uuid.uuid4().bytes
            try:
                accepted = await asyncio.to_thread(
                    send_goal.call, goal_id=_uuid(goal_id), goal=goal_class(order=3)
                )
                assert accepted is not None and accepted.accepted
                await recv_until(server, lambda m: m.get("op") == "send_action_goal")
                assert link.actions.pending == 1
                second = await asyncio.to_thread(
                    send_goal.call, goal_id=_uuid(uuid.uuid4().bytes), goal=goal_class(order=3)
                )
                assert second is not None and not second.accepted  # max_pending_goals
                result = await asyncio.to_thread(get_result.call, goal_id=_uuid(goal_id))
                assert result is not None and result.status == 6  # ABORTED
                await recv_until(server, lambda m: m.get("op") == "cancel_action_goal")
                assert link.actions.pending == 0
            finally:
                send_goal.close()
                get_result.close()
    finally:
        await app.stop()
