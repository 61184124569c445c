"""One datagram for many writers' samples: the DDS link's writers share one transmit pack.

Cyclone DDS gives each writer its own transmit pack (``dds_writer.m_xp``) and sends it at the
end of each write (``dds_write.c``): a simulation step's 30 ``/odom``, 15 ``/scan`` and one
``/tf`` on 46 writers are 46 datagrams, each a ``sendmsg`` that also does the receiver's
network-stack work on loopback and wakes its receive thread. Cyclone's packing
(``ddsi_xpack_addmsg``, ``ddsi_xmsg.c``) merges the messages of *any* writers of a participant
that go to the same address (an ``INFO_TS`` or ``INFO_DST`` between them as needed) up to
``General/MaxMessageSize``; it is only that each writer has a pack of its own, and that the
batching switch (``whc_batch``, set by ``dds_write_set_batch`` for writers made after it) is
per writer. :class:`SharedPack` makes the link's writers use one pack and batch, and the link
sends it once per turn of the event loop (``dds_write_flush`` of any of them), as the rosbridge
server corks a client's frames until the end of the turn.

Neither is in Cyclone's public API (its Python binding has no writer-batching QoS, and
``dds_write_set_batch`` does not reach writers that exist), so :meth:`SharedPack.adopt` writes
two fields of Cyclone's ``struct dds_writer`` (``dds__types.h``: ``m_topic``, ``m_xp``, ``m_wr``,
``m_whc``, ``whc_batch`` in that order) through ``ctypes``: only with the binding this was read
against (:data:`VERSIONS`), and only after checking the layout on each writer (the topic
pointer where ``m_topic`` is, the domain's pointer in the pack the writer has); anything else
and the writer keeps its own pack and writes as before. Deleting a writer frees the pack it holds: a
writer gets its own back (:meth:`SharedPack.release`, :meth:`SharedPack.close`, also at exit)
before it is deleted, and the pack keeps a reference to each writer it lent itself to, so that
the binding does not delete one when the link lets go of it.
Every call here comes from the event loop's thread, the only one that writes or deletes.
"""

from __future__ import annotations

import atexit
import ctypes
import importlib
import importlib.metadata
import logging
from dataclasses import dataclass
from typing import Any


__all__ = ["VERSIONS", "SharedPack"]

logger = logging.getLogger(__name__)

#: The binding versions whose C library (bundled in the wheel) this layout was read from.
VERSIONS = ("11.0.1",)
#: Bytes from a ``struct ddsi_xpack`` to its ``gv`` (the domain it sends for), in 11.0.1.
_PACK_GV = 96
#: Bytes from ``m_xp`` to ``whc_batch`` (after ``m_wr`` and ``m_whc``).
_BATCH_AFTER_PACK = 24
#: How far into a ``struct dds_writer`` its ``m_topic`` is looked for, in pointers (it is the
#: 78th in 11.0.1, after the entity and endpoint parts).
_SEARCH_WORDS = 128
_WORD = ctypes.sizeof(ctypes.c_void_p)


@dataclass(slots=True)
class _Adopted:
    """A writer that uses the shared pack: where its fields are and what they held."""

    #: The binding's writer, kept: dropped, the binding would delete it with the shared pack.
    writer: Any
    pack_field: int
    own_pack: int


class SharedPack:
    """The transmit pack the DDS link's writers share (see the module's docstring).

    Make it with :meth:`create` (None: not this binding, or the layout is not the one
    expected); :meth:`adopt` each writer after making it, :meth:`release` it before deleting
    it, :meth:`flush` once the loop's turn wrote what it had to, :meth:`close` before the
    participant goes.
    """

    def __init__(self, lib: Any, pack: int, gv: int) -> None:
        self._lib = lib
        #: The shared ``struct ddsi_xpack *``.
        self.pack = pack
        self._gv = gv
        self._adopted: dict[int, _Adopted] = {}
        #: A writer that uses the pack (``dds_write_flush`` of it sends the pack), or 0.
        self._flusher = 0
        atexit.register(self.close)

    @classmethod
    def create(cls, probe: Any) -> SharedPack | None:
        """Make the pack for ``probe``'s domain (a writer of the binding, just made).

        None (and a debug line) when the binding is not one of :data:`VERSIONS` or the layout
        does not check out on ``probe``.
        """
        try:
            version = importlib.metadata.version("cyclonedds")
        except importlib.metadata.PackageNotFoundError:
            return None
        if version not in VERSIONS:
            logger.debug("DDS: binding %s: writers keep one pack each", version)
            return None
        try:
            lib = _library()
            # creating ``probe`` woke this thread for the domain: its state names the domain
            state = lib.ddsi_lookup_thread_state()
            gv = ctypes.c_void_p.from_address(state + _WORD).value or 0
            field = _pack_field(lib, probe, gv)
        except Exception as err:  # a library without these symbols
            logger.debug("DDS: no shared pack: %s", err)
            return None
        if field is None:
            logger.debug("DDS: writer layout not as expected: writers keep one pack each")
            return None
        pack = lib.ddsi_xpack_new(gv, False)
        if not pack:
            return None
        return cls(lib, pack, gv)

    def adopt(self, writer: Any) -> bool:
        """Make ``writer`` batch into the shared pack; False: its layout did not check out."""
        if self.pack == 0:
            return False
        field = _pack_field(self._lib, writer, self._gv)
        if field is None:
            return False
        batch = ctypes.c_bool.from_address(field + _BATCH_AFTER_PACK)
        if batch.value:
            return False  # batching already (dds_write_set_batch): not ours to change
        own = ctypes.c_void_p.from_address(field)
        self._adopted[writer._ref] = _Adopted(writer, field, own.value or 0)
        own.value = self.pack
        batch.value = True
        if not self._flusher:
            self._flusher = writer._ref
        return True

    def release(self, writer: Any) -> None:
        """Give ``writer`` its own pack back, unbatched (before it is deleted)."""
        adopted = self._adopted.pop(writer._ref, None)
        if adopted is None:
            return
        self.flush()  # what it wrote goes out before the writer does
        ctypes.c_bool.from_address(adopted.pack_field + _BATCH_AFTER_PACK).value = False
        ctypes.c_void_p.from_address(adopted.pack_field).value = adopted.own_pack
        if self._flusher == writer._ref:
            self._flusher = next(iter(self._adopted), 0)

    def flush(self) -> None:
        """Send what the shared pack holds (nothing to do when it is empty)."""
        if self._flusher:
            self._lib.dds_write_flush(self._flusher)

    def close(self) -> None:
        """Give every writer its own pack back and free the shared one (idempotent)."""
        if self.pack == 0:
            return
        self.flush()
        for adopted in self._adopted.values():
            ctypes.c_bool.from_address(adopted.pack_field + _BATCH_AFTER_PACK).value = False
            ctypes.c_void_p.from_address(adopted.pack_field).value = adopted.own_pack
        self._adopted.clear()
        self._flusher = 0
        self._lib.ddsi_xpack_free(self.pack)
        self.pack = 0
        atexit.unregister(self.close)


def _pack_field(lib: Any, writer: Any, gv: int) -> int | None:
    """Return the address of ``writer``'s ``m_xp``; None if the layout does not check out."""
    entity = _entity(lib, writer._ref)
    topic = _entity(lib, writer.topic._ref)
    if not (entity and topic and gv):
        return None
    # word by word, stopping at m_topic: nothing past the writer's fields is read
    words = (ctypes.c_size_t * _SEARCH_WORDS).from_address(entity)
    index = next((k for k in range(_SEARCH_WORDS - 1) if words[k] == topic), None)
    if index is None:
        return None
    field = entity + (index + 1) * _WORD
    pack = ctypes.c_void_p.from_address(field).value
    if not pack or ctypes.c_void_p.from_address(pack + _PACK_GV).value != gv:
        return None
    return field


def _entity(lib: Any, handle: int) -> int:
    """Return the address of the entity of ``handle`` (0 if it has none)."""
    found = ctypes.c_void_p()
    if lib.dds_entity_pin(handle, ctypes.byref(found)) != 0:
        return 0
    lib.dds_entity_unpin(found)
    return found.value or 0


_LIB: Any = None


def _library() -> Any:
    """The binding's C library (loaded once by the binding: the same one), with signatures."""
    global _LIB
    if _LIB is None:
        lib = importlib.import_module("cyclonedds.internal").load_cyclonedds()
        vp, i32 = ctypes.c_void_p, ctypes.c_int32
        for name, restype, argtypes in (
            ("dds_entity_pin", i32, [i32, ctypes.POINTER(vp)]),
            ("dds_entity_unpin", None, [vp]),
            ("ddsi_lookup_thread_state", ctypes.c_size_t, []),
            ("ddsi_xpack_new", ctypes.c_size_t, [vp, ctypes.c_bool]),
            ("ddsi_xpack_free", None, [vp]),
            ("dds_write_flush", i32, [i32]),
        ):
            function = getattr(lib, name)
            function.restype, function.argtypes = restype, argtypes
        _LIB = lib
    return _LIB
