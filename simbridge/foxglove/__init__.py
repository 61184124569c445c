"""The Foxglove WebSocket protocol beside rosbridge (``--foxglove-port``), on the Foxglove SDK.

:mod:`.mapping` (names, scopes, status frames) imports nothing beyond simbridge; :mod:`.front`
(the SDK's server beside the graph) imports ``foxglove-sdk``, the ``[foxglove]`` extra, when it
runs. Nothing here is imported unless ``--foxglove-port`` asks for it.
"""

from __future__ import annotations

from simbridge.foxglove.mapping import (
    ADMIN_SCOPE,
    CLIENT_ENCODINGS,
    INSTALL_HINT,
    MESSAGE_ENCODING,
    SCHEMA_ENCODING,
    param_name,
    split_param,
    status_of,
)


__all__ = [
    "ADMIN_SCOPE",
    "CLIENT_ENCODINGS",
    "INSTALL_HINT",
    "MESSAGE_ENCODING",
    "SCHEMA_ENCODING",
    "param_name",
    "split_param",
    "status_of",
]
