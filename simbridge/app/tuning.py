"""The production tuning of a simbridge process: what it imports, and its heap once started.

The ``simbridge`` command applies all of it; a program embedding simbridge (its own
:class:`~simbridge.app.runner.App`) gets the same by calling :func:`import_hashlib` and
:func:`import_asyncio` before anything imports them, and :func:`settle` once the server runs:

- :func:`import_hashlib`: hashlib with CPython's own hash functions, not OpenSSL's (3.5 MB);
- :func:`import_asyncio`: asyncio without ssl when no TLS is served (about 1 MB);
- :func:`settle`: the heap start-up freed given back to the system, what start-up built frozen
  out of the garbage collector's walks, and the collector's thresholds of a running server
  (:data:`GC_THRESHOLDS`).

Each changes the whole process (imports, the collector): it is the embedder's choice, not
something importing simbridge does.
"""

from __future__ import annotations

import gc
import importlib
import sys


__all__ = [
    "GC_THRESHOLDS",
    "import_asyncio",
    "import_hashlib",
    "release_startup_memory",
    "settle",
]

#: Garbage-collector thresholds once the server runs (see :func:`settle`).
GC_THRESHOLDS = (20_000, 10, 10)


def import_asyncio(*, tls: bool) -> None:
    """Import asyncio, without the ssl module when this run serves no TLS.

    asyncio imports ssl when it is imported, only to be able to serve TLS: ``asyncio.sslproto``,
    ``base_events`` and ``selector_events`` keep ``ssl = None`` when that import fails, and then
    refuse an ``ssl=`` argument ("Python ssl module is not available"). A server without
    ``--certfile`` never passes one, so for that import ssl is hidden: _ssl, libssl and the ssl
    module's enums stay out of an idle server (about 1 MB resident on x86-64, issue 16). Where
    asyncio or ssl is already imported (tests, a program embedding simbridge), nothing changes.
    """
    if not tls and "asyncio" not in sys.modules and "ssl" not in sys.modules:
        sys.modules["ssl"] = None  # type: ignore[assignment]  # `import ssl` raises ImportError
        try:
            importlib.import_module("asyncio")
        finally:
            del sys.modules["ssl"]


#: CPython's own hash modules, which hashlib falls back to without OpenSSL's ``_hashlib``.
BUILTIN_HASHES = ("_md5", "_sha1", "_sha3", "_blake2") + (
    ("_sha2",) if sys.version_info >= (3, 12) else ("_sha256", "_sha512")
)


def import_hashlib() -> None:
    """Import hashlib and hmac with CPython's own hash functions instead of OpenSSL's.

    With ``_hashlib`` importable, ``import hashlib`` (websockets' handshake: SHA-1; its
    ``secrets`` import, rosauth's SHA-512, the page's ETags) loads OpenSSL's libcrypto and
    initialises its digests: 3.5 MB of an idle server's resident memory on x86-64 (issue 16),
    for a few hashes of short strings that CPython's built-in modules compute alike (the same
    digests; ``hashlib.algorithms_guaranteed`` all there). So for this import ``_hashlib`` is
    hidden, as :func:`import_asyncio` hides ssl. A TLS run loads libcrypto through ``ssl``
    as before. Where hashlib or ``_hashlib`` is already imported (tests, a program embedding
    simbridge), or a Python was built without the built-in modules, nothing changes.
    """
    import importlib.util  # here: `simbridge healthcheck` does not need it

    if any(name in sys.modules for name in ("hashlib", "hmac", "_hashlib")):
        return
    if any(importlib.util.find_spec(name) is None for name in BUILTIN_HASHES):
        return
    sys.modules["_hashlib"] = None  # type: ignore[assignment]  # `import _hashlib` raises
    try:
        importlib.import_module("hashlib")
        importlib.import_module("hmac")
    finally:
        del sys.modules["_hashlib"]


def release_startup_memory() -> None:
    """Give the heap that start-up freed back to the system (glibc's ``malloc_trim``).

    Building the world, the message types and the configuration allocates and frees a few MB that
    glibc keeps for reuse; an idle server (a Pi runs it all day) need not hold them: about 2 MB
    of its resident memory. A no-op where the C library has no ``malloc_trim`` (musl).
    """
    import ctypes  # numpy has imported it already

    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (AttributeError, OSError):
        return
    trim(0)


def settle() -> None:
    """Tune a started server's process: its heap given back, its start-up frozen, GC thresholds.

    Call once, when the server has started (its world, graph and message types built).
    """
    release_startup_memory()
    # what startup built (interface registry, world, graph) lives as long as the process: full
    # garbage collections need not walk it again (each cost the loop 30-50 ms, a gap in /odom)
    gc.freeze()
    # a tick's messages live until the tick is sent and die by reference counting: with the
    # default threshold (700 container objects) collections ran in the middle of every tick,
    # each promoting the tick's live messages to older generations, which then filled and were
    # walked (bench.zenoh classroom, a simulator of 300 robots in 21 s: 3,500 young, 320
    # middle and 29 full collections, 370 ms in all, pauses up to 20 ms; with 20,000: 106, 10
    # and 1, 28 ms). Only objects that outlive their use count towards the threshold.
    gc.set_threshold(*GC_THRESHOLDS)
