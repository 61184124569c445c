"""rosbridge clients' subscriptions to the graph's topics, and how a message reaches them.

The rosbridge front end is one subscriber of each topic its clients subscribe to (a
:class:`TopicSubscribers`, the topic's sink for this front end): the graph hands it each
message once (:meth:`TopicTable.deliver <simbridge.graph.topics.TopicTable.deliver>`), and it
sends the message to every client subscription of the topic. A client receives each message
once per topic spelling it subscribed with; a frame is encoded at most once per (compression,
spelling) (:func:`~simbridge.rosbridge.encoding.publish_frame`) and written to every client that
takes it as it is with one ``send_many`` (a ``websockets.broadcast``); throttled and fragmented
subscriptions are served one by one.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Hashable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, cast

from simbridge.errors import ProtocolError
from simbridge.graph.topics import Peer, Topic, TopicTable
from simbridge.rosbridge.encoding import Frame, Outgoing
from simbridge.rosbridge.fragments import split_frame
from simbridge.rosbridge.frames import publish_frame
from simbridge.rosbridge.session import Session, Subscription


if TYPE_CHECKING:
    from collections.abc import Collection


__all__ = ["Client", "SendEntries", "Subscribers", "TopicSubscribers"]

logger = logging.getLogger(__name__)


class Client(Peer, Protocol):
    """A rosbridge client, as its front end sees it: a graph peer with a session and a queue."""

    #: The client's protocol state.
    session: Session

    def send(self, frame: Frame, key: Hashable | None = None, limit: int = 0) -> None:
        """Queue one frame for the client (``key``/``limit``: drop-oldest per subscription)."""


#: Subscribers that get one shared frame: ``(client, subscription, queue bound)``.
SendEntries = list[tuple[Client, Hashable, int]]


@dataclass(eq=False, slots=True)
class _Plan:
    """The subscribers of a topic sorted for delivery, valid for one ``version``.

    Most subscribers take the frame as it is: they are grouped by (compression, topic
    spelling), each group written with one ``send_many``. Throttled and fragmented ones are
    served one by one.
    """

    version: tuple[int, int]
    groups: list[tuple[str, str, SendEntries]]
    one_by_one: list[tuple[Client, Subscription]]


class TopicSubscribers:
    """The rosbridge clients subscribed to one topic: the topic's sink for this front end."""

    __slots__ = ("owner", "plan", "subscriptions")

    def __init__(self, owner: Subscribers) -> None:
        self.owner = owner
        #: Client subscriptions by (client, topic spelling).
        self.subscriptions: dict[tuple[Client, str], Subscription] = {}
        #: How a message reaches them (rebuilt when subscriptions change).
        self.plan: _Plan | None = None

    def __len__(self) -> int:
        return len(self.subscriptions)

    def peers(self) -> Iterable[Peer]:
        """Return the subscribed clients (once per topic spelling)."""
        return [peer for peer, _spelling in self.subscriptions]

    def deliver(
        self,
        topic: Topic,
        out: Outgoing,
        now: float,
        source: Peer | None,
        only: Collection[Peer] | None = None,
    ) -> None:
        """Send ``out`` to the subscriptions (``only``: to those of these peers alone)."""
        owner = self.owner
        default_limit = owner.default_queue_length
        send_many = owner.send_many
        if only is not None or send_many is None:
            for (peer, _written), sub in self.subscriptions.items():
                if only is not None and peer not in only:
                    continue
                if sub.throttle_rate and not sub.admit(now):
                    continue
                owner.send_to(peer, sub, out, default_limit)
            return
        plan = self.plan
        if plan is None or plan.version != (owner.generation, Session.epoch):
            plan = self.plan = self._plan(default_limit)
        for peer, sub in plan.one_by_one:
            if sub.throttle_rate and not sub.admit(now):
                continue
            owner.send_to(peer, sub, out, default_limit)
        for compression, spelling, entries in plan.groups:
            try:
                frame = publish_frame(out, compression, spelling)
            except ProtocolError:
                for peer, key, _limit in entries:
                    owner.send_to(peer, cast(Subscription, key), out, default_limit)
                continue
            send_many(frame, entries)

    def _plan(self, default_limit: int) -> _Plan:
        groups: dict[tuple[str, str], SendEntries] = {}
        one_by_one: list[tuple[Client, Subscription]] = []
        for (peer, _written), sub in self.subscriptions.items():
            fragmented = sub.fragment_size is not None or peer.session.fragment_size is not None
            if sub.throttle_rate or fragmented:
                one_by_one.append((peer, sub))
                continue
            entries = groups.setdefault((sub.compression, sub.topic), [])
            entries.append((peer, sub, sub.queue_length or default_limit))
        return _Plan(
            (self.owner.generation, Session.epoch),
            [(c, t, entries) for (c, t), entries in groups.items()],
            one_by_one,
        )


class Subscribers:
    """Every rosbridge client subscription, kept with the graph's topics."""

    def __init__(self, topics: TopicTable, *, default_queue_length: int = 100) -> None:
        #: The graph's topics.
        self.topics = topics
        #: Per-subscription bound of pending frames when a client asked for queue_length 0.
        self.default_queue_length = default_queue_length
        #: Sends one frame to many subscribers at once, ``(frame, [(peer, key, limit)])`` (the
        #: builder sets the server's: one ``websockets.broadcast`` per frame instead of one call
        #: per client).
        self.send_many: Callable[[Frame, SendEntries], None] | None = None
        #: Bumped by every subscription change: the delivery plans are rebuilt.
        self.generation = 0

    def sink(self, topic: Topic) -> TopicSubscribers | None:
        """Return this front end's subscribers of ``topic``, if any."""
        return cast("TopicSubscribers | None", topic.sinks.get(self))

    def subscribed(self, peer: Client, sub: Subscription, type_name: str | None) -> Topic:
        """Deliver topic ``sub.resolved`` to ``peer`` as its session's subscription ``sub``.

        ``type_name`` (canonical, admitted) fixes the topic's type if nothing did yet.
        """
        topic = self.topics.take(sub.resolved, type_name)
        sink = self.sink(topic)
        if sink is None:
            sink = TopicSubscribers(self)
        sink.subscriptions[(peer, sub.topic)] = sub
        self.topics.add_sink(topic, self, sink)  # a change of the topic, counted there
        self.generation += 1  # the options may have changed: plans are rebuilt
        return topic

    def unsubscribed(self, peer: Client, sub: Subscription, gone: bool) -> None:
        """A subscribe id of ``sub`` went; ``gone``: ``peer`` no longer receives the topic."""
        self.generation += 1
        self.topics.changes += 1
        if not gone:
            return
        topic = self.topics.topics.get(sub.resolved)
        sink = None if topic is None else self.sink(topic)
        if topic is None or sink is None:
            return
        sink.subscriptions.pop((peer, sub.topic), None)
        sink.plan = None  # holds the peer: drop it now, not at the next publish
        if not sink.subscriptions:
            self.topics.remove_sink(topic, self)

    def replay_latched(self, peer: Client, topic: Topic, sub: Subscription) -> None:
        """Send the latched message of ``topic`` to a new subscription."""
        if topic.latched is not None:
            self.send_to(peer, sub, topic.latched, self.default_queue_length)

    def send_to(self, peer: Client, sub: Subscription, out: Outgoing, default_limit: int) -> None:
        """Encode ``out`` as ``sub`` wants it (cached) and queue it for ``peer``."""
        try:
            frame = publish_frame(out, sub.compression, sub.topic)
        except ProtocolError as err:
            if sub.first_warning():  # once per subscription, not once per message
                for reply in peer.session.status("error", f"subscribe {sub.topic}: {err}"):
                    peer.send(reply.frame)
            return
        size = sub.fragment_size or peer.session.fragment_size
        limit = sub.queue_length or default_limit
        if size is not None and frame.text and len(frame.data) > size:
            frag_id = f"{sub.topic}:{out.stamp[0]}.{out.stamp[1]:09d}"
            for piece in split_frame(frame, size, frag_id):
                peer.send(piece, sub, 0)
            return
        peer.send(frame, sub, limit)
