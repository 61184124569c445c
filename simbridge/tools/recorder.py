"""``simbridge --record DIR``: the topics of the server's own graph into a rosbag2 MCAP bag.

In process, no socket involved: the recorder subscribes to the graph as a node
(``/simbridge_recorder``) and writes each message stamped with its receive time, as
``ros2 bag record`` does. The server's builder (:func:`simbridge.app.build.build`) makes it;
``simbridge record`` records any rosbridge server as a client instead
(:mod:`simbridge.tools.record`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from simbridge.graph import Graph
from simbridge.tools.bag import BagError, BagWriter


__all__ = ["GraphRecorder"]


class GraphRecorder:
    """Records topics of an in-process graph (``simbridge --record DIR``): no socket involved.

    The bag is created by :meth:`start` (the server calls it once its ports listen, so a
    server that cannot start leaves no bag behind); :meth:`tick` before that does nothing.

    Args:
        graph: the server's graph.
        out: the bag directory to create.
        topics: topics to record; None for every topic, including those that appear later
            (looked for once a second by :meth:`tick`).

    Raises:
        BagError: ``out`` exists.
    """

    def __init__(self, graph: Graph, out: Path, topics: Sequence[str] | None = None) -> None:
        if out.exists():
            msg = f"bag '{out}' exists already; choose another output name (-o)"
            raise BagError(msg)
        self.graph = graph
        self.out = out
        self.topics = None if topics is None else list(topics)
        #: The bag, from :meth:`start` on.
        self.writer: BagWriter | None = None
        self._following: set[str] = set()
        self._last_scan = 0.0

    @property
    def count(self) -> int:
        """Messages recorded so far."""
        return self.writer.count if self.writer is not None else 0

    def start(self) -> None:
        """Create the bag and follow the topics known by now."""
        self.writer = BagWriter(self.out, self.graph.registry)
        self._follow_known()

    def _follow_known(self) -> None:
        writer = self.writer
        if writer is None:
            return
        table = self.graph.topics.topics
        for name in self.topics if self.topics is not None else list(table):
            topic = table.get(name)
            if name in self._following or topic is None or topic.type is None:
                continue
            if not topic.known:
                continue  # a type rosbags cannot serialise
            self._following.add(name)
            type_name = topic.type

            def on_msg(
                msg: Any, source: object, name: str = name, type_name: str = type_name
            ) -> None:
                writer.write(name, type_name, msg, time.time_ns())

            self.graph.subscribe(name, type_name, "/simbridge_recorder", on_msg)
            if topic.latched is not None:
                on_msg(topic.latched.msg, None)

    def tick(self, now: float) -> None:
        """Close a segment when due; pick up new topics once a second."""
        if self.writer is None:
            return
        self.writer.tick()
        if now - self._last_scan >= 1.0:
            self._last_scan = now
            self._follow_known()

    def close(self) -> None:
        """Finish the bag (one ``NAME.mcap``), if :meth:`start` made one."""
        if self.writer is not None:
            self.writer.close()
