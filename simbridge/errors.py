"""The one error family of simbridge.

Every error simbridge raises on purpose derives from :class:`SimbridgeError`::

    SimbridgeError
    ├── ConfigError          a settings, world or parameter file is wrong (startup)
    ├── ProtocolError        a client sent something the rosbridge protocol does not allow
    │   └── ConversionError  a message payload does not match its ROS type
    ├── TypeNotFoundError    a ROS interface type is unknown or misspelled
    └── ServiceError         a service call cannot be answered successfully

Messages say what failed and how to fix it. A :class:`ProtocolError` becomes a
``status`` reply to the client that caused it; it never closes other connections
or stops the simulation loop.
"""

from __future__ import annotations


__all__ = [
    "ConfigError",
    "ConversionError",
    "ProtocolError",
    "ServiceError",
    "SimbridgeError",
    "TypeNotFoundError",
]


class SimbridgeError(Exception):
    """Base class of every error simbridge raises on purpose."""


class ConfigError(SimbridgeError):
    """A configuration, world or parameter file is invalid."""


class ProtocolError(SimbridgeError):
    """A client message breaks the rosbridge v2 protocol."""


class ConversionError(ProtocolError):
    """A message payload does not match its ROS type."""


class TypeNotFoundError(SimbridgeError):
    """A ROS interface type is not known to simbridge."""


class ServiceError(SimbridgeError):
    """A service call failed; the text is sent back as the ``values`` of the response."""
