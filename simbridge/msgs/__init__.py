"""ROS 2 interface types for simbridge: the registry, validation and conversion of payloads.

Built on rosbags' definition of every standard ROS 2 message, shipped as data made from it
(:mod:`simbridge.msgs.definitions`: a run imports rosbags only for what it alone does); type
names are accepted as ``pkg/Type`` and ``pkg/msg/Type``.
"""

from __future__ import annotations

from simbridge.msgs.convert import Converter, Stamp, positional_args
from simbridge.msgs.registry import (
    FieldSpec,
    MessageSpec,
    TypeRegistry,
    normalize_type,
    short_type,
)
from simbridge.msgs.typedefs import typedefs


__all__ = [
    "Converter",
    "FieldSpec",
    "MessageSpec",
    "Stamp",
    "TypeRegistry",
    "normalize_type",
    "positional_args",
    "short_type",
    "typedefs",
]
