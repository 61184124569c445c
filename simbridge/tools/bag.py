"""rosbag2 files in MCAP format, written with rosbags so that an interrupted recording survives.

:class:`BagWriter` writes a rosbag2 directory that ``ros2 bag``, Foxglove, PlotJuggler and
rosbags read. rosbags' MCAP writer keeps messages in memory until a chunk fills and writes the
index, footer and ``metadata.yaml`` only on close, so a killed recorder would leave nothing
readable. The writer therefore records in *segments* (``NAME_0.mcap``, ``NAME_1.mcap``...),
each a complete MCAP file closed every ``segment_seconds``, and rewrites ``metadata.yaml``
(atomically) to list the closed ones: after SIGKILL the bag holds everything up to the last
closed segment and reads as a split rosbag2 bag. A clean :meth:`BagWriter.close` (SIGINT,
SIGTERM) merges the segments into one ``NAME.mcap``, which single-file tools (Foxglove,
PlotJuggler) open directly.

Messages go in as simbridge's canonical dicts (:mod:`simbridge.msgs.convert`) and come out of
:func:`read_messages` as plain dicts with ROS field names (arrays as lists).
"""

from __future__ import annotations

import logging
import os
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.typesys import Stores, get_typestore

from simbridge.errors import SimbridgeError
from simbridge.msgs import TypeRegistry
from simbridge.msgs.cdr import CdrWriter, to_dict


__all__ = ["BagError", "BagWriter", "read_messages", "to_dict"]

logger = logging.getLogger(__name__)

_META = "metadata.yaml"


class BagError(SimbridgeError):
    """A bag cannot be written or read."""


class BagWriter:
    """A rosbag2 MCAP bag written in closed segments (see the module docstring).

    Args:
        path: the bag directory to create (it must not exist, as with ``ros2 bag record -o``).
        registry: message definitions (rosbags' plus simbridge's).
        segment_seconds: close a segment this often (what a SIGKILL may lose at most).

    Raises:
        BagError: ``path`` exists.
    """

    def __init__(
        self, path: Path | str, registry: TypeRegistry, *, segment_seconds: float = 1.0
    ) -> None:
        self.path = Path(path)
        self.registry = registry
        self._cdr = CdrWriter(registry)
        self.segment_seconds = segment_seconds
        if self.path.exists():
            msg = f"bag '{self.path}' exists already; choose another output name (-o)"
            raise BagError(msg)
        self.path.mkdir(parents=True)
        self._types: dict[str, str] = {}
        self._writer: Writer | None = None
        self._connections: dict[str, Any] = {}
        self._segment = 0
        self._segment_start = 0.0
        self._closed: list[dict[str, Any]] = []  # metadata of the closed segments
        #: Messages written so far.
        self.count = 0

    @property
    def name(self) -> str:
        """The bag's name (its directory name)."""
        return self.path.name

    def write(self, topic: str, type_name: str, msg: dict[str, Any], stamp_ns: int) -> None:
        """Add one canonical message received at ``stamp_ns`` (nanoseconds since the epoch)."""
        known = self._types.setdefault(topic, type_name)
        if known != type_name:
            return  # a topic keeps the type it was first recorded with
        writer = self._open_segment()
        conn = self._connections.get(topic)
        if conn is None:
            conn = writer.add_connection(topic, type_name, typestore=self.registry.store)
            self._connections[topic] = conn
        writer.write(conn, stamp_ns, self._cdr.serialize(type_name, msg))
        self.count += 1

    def tick(self) -> None:
        """Close the current segment once it is ``segment_seconds`` old (call regularly)."""
        if self._writer is not None and time.monotonic() - self._segment_start >= (
            self.segment_seconds
        ):
            self._close_segment()

    def _open_segment(self) -> Writer:
        if self._writer is None:
            tmp = self.path / f".{self.name}_{self._segment}"
            self._writer = Writer(tmp, version=9, storage_plugin=StoragePlugin.MCAP)
            self._writer.open()
            self._connections = {}
            self._segment_start = time.monotonic()
        return self._writer

    def _close_segment(self) -> None:
        writer, self._writer = self._writer, None
        if writer is None:
            return
        writer.close()
        tmp = self.path / f".{self.name}_{self._segment}"
        final = f"{self.name}_{self._segment}.mcap"
        (tmp / f"{tmp.name}.mcap").replace(self.path / final)
        info = yaml.safe_load((tmp / _META).read_text(encoding="utf-8"))
        info = info["rosbag2_bagfile_information"]
        info["files"][0]["path"] = final
        self._closed.append(info)
        shutil.rmtree(tmp)
        self._segment += 1
        self._write_metadata()

    def _write_metadata(self) -> None:
        if not self._closed:
            return
        first = self._closed[0]
        start = min(s["starting_time"]["nanoseconds_since_epoch"] for s in self._closed)
        end = max(
            s["starting_time"]["nanoseconds_since_epoch"] + s["duration"]["nanoseconds"]
            for s in self._closed
        )
        topics: dict[str, dict[str, Any]] = {}
        for seg in self._closed:
            for entry in seg["topics_with_message_count"]:
                name = entry["topic_metadata"]["name"]
                if name in topics:
                    topics[name]["message_count"] += entry["message_count"]
                else:
                    topics[name] = {
                        "topic_metadata": entry["topic_metadata"],
                        "message_count": entry["message_count"],
                    }
        info = {
            **first,
            "relative_file_paths": [s["files"][0]["path"] for s in self._closed],
            "duration": {"nanoseconds": end - start},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": sum(s["message_count"] for s in self._closed),
            "topics_with_message_count": list(topics.values()),
            "files": [s["files"][0] for s in self._closed],
        }
        tmp = self.path / f".{_META}.tmp"
        text = yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False)
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, self.path / _META)

    def abort(self) -> None:
        """Drop the open segment's file handle without finishing it (as a crash would)."""
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.abort()

    def close(self, *, merge: bool = True) -> None:
        """Close the last segment; with ``merge``, join the segments into one ``NAME.mcap``."""
        self._close_segment()
        if not self._closed:
            # nothing recorded: still leave a valid, empty bag
            self._open_segment()
            self._close_segment()
        if merge:
            self._merge()

    def _merge(self) -> None:
        tmp = self.path / f".{self.name}_merged"
        with (
            AnyReader([self.path], default_typestore=self.registry.store) as reader,
            Writer(tmp, version=9, storage_plugin=StoragePlugin.MCAP) as writer,
        ):
            conns: dict[str, Any] = {}
            for c in reader.connections:
                if c.topic not in conns:
                    conns[c.topic] = writer.add_connection(
                        c.topic, c.msgtype, typestore=self.registry.store
                    )
            for c, stamp, raw in reader.messages():
                writer.write(conns[c.topic], stamp, raw)
        merged = self.path / f"{self.name}.mcap"
        (tmp / f"{tmp.name}.mcap").replace(merged)
        info = yaml.safe_load((tmp / _META).read_text(encoding="utf-8"))
        info["rosbag2_bagfile_information"]["relative_file_paths"] = [merged.name]
        info["rosbag2_bagfile_information"]["files"][0]["path"] = merged.name
        text = yaml.safe_dump(info, sort_keys=False)
        (self.path / f".{_META}.tmp").write_text(text, encoding="utf-8")
        os.replace(self.path / f".{_META}.tmp", self.path / _META)
        shutil.rmtree(tmp)
        for seg in self._closed:
            (self.path / seg["files"][0]["path"]).unlink(missing_ok=True)


def _bag_dir(path: Path | str) -> Path:
    p = Path(path)
    if p.is_file() and p.suffix == ".mcap":
        return p.parent
    return p


def read_messages(
    path: Path | str, topics: set[str] | None = None
) -> Iterator[tuple[str, str, int, dict[str, Any]]]:
    """Yield ``(topic, type, log time ns, message dict)`` of a bag in time order.

    ``path`` is the bag directory or its ``.mcap`` file.

    Raises:
        BagError: the bag cannot be read.
    """
    bag = _bag_dir(path)
    try:
        with AnyReader([bag], default_typestore=get_typestore(Stores.LATEST)) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            for conn, stamp, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                yield conn.topic, conn.msgtype, stamp, to_dict(msg)
    except BagError:
        raise
    except Exception as err:  # rosbags raises several unrelated types
        msg = f"cannot read bag '{path}': {err}"
        raise BagError(msg) from None
