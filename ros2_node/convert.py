"""rclpy message classes by type name, and rclpy messages ↔ plain dicts by their own introspection.

The node's outputs never pass through here: they are built once (:mod:`flexmb_io.messages`) and
published as the bytes :mod:`flexmb_io.wire` serializes. The node needs the classes for its
publishers and subscriptions, and :func:`to_dict` for the commands it receives; :func:`to_ros`
gives an rclpy message of a :mod:`flexmb_io.messages` message or dict (tests, tools).
"""

from __future__ import annotations

import array
import importlib
from functools import lru_cache

import numpy as np

_BASIC = {"boolean", "octet", "char", "float", "double", "long double", "int8", "uint8", "int16", "uint16",
          "int32", "uint32", "int64", "uint64", "string", "wstring"}


@lru_cache(maxsize=None)
def message_class(type_name: str):
    """The rclpy class of ``pkg/msg/Type`` (or ``pkg/Type``)."""
    parts = type_name.split("/")
    pkg, name = parts[0], parts[-1]
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _element_type(slot_type: str) -> str | None:
    """For 'sequence<geometry_msgs/Point>' or 'geometry_msgs/Point[3]' → 'geometry_msgs/Point';
    None for sequences/arrays of basic types."""
    t = slot_type
    if t.startswith("sequence<"):
        t = t[len("sequence<"):-1].split(",")[0]
    elif t.endswith("]"):
        t = t[:t.index("[")]
    else:
        return None
    return None if t in _BASIC or t.startswith("string") else t


@lru_cache(maxsize=None)
def _fields(cls) -> tuple[tuple[str, str], ...]:
    return tuple(cls.get_fields_and_field_types().items())


def to_ros(type_name: str, d):
    """A new rclpy message of ``type_name`` filled from ``d``, a dict or a :mod:`flexmb_io.wire` message
    (missing keys keep defaults)."""
    from flexmb_io.wire import plain

    return fill(message_class(type_name)(), plain(d))


def fill(msg, d: dict):
    for name, slot in _fields(type(msg)):
        if name not in d:
            continue
        value = d[name]
        if isinstance(value, dict):
            fill(getattr(msg, name), value)
            continue
        if isinstance(value, list) and value and isinstance(value[0], dict):
            elem = _element_type(slot)
            cls = message_class(elem)
            setattr(msg, name, [fill(cls(), v) for v in value])
            continue
        setattr(msg, name, value)
    return msg


def to_dict(msg) -> dict:
    """A plain dict of an rclpy message (numbers as Python floats/ints, arrays as lists)."""
    out = {}
    for name, _slot in _fields(type(msg)):
        value = getattr(msg, name)
        if hasattr(value, "get_fields_and_field_types"):
            out[name] = to_dict(value)
        elif isinstance(value, (list, tuple)):
            out[name] = [to_dict(v) if hasattr(v, "get_fields_and_field_types") else v for v in value]
        elif isinstance(value, (array.array, np.ndarray)):
            out[name] = list(value.tolist())
        else:
            out[name] = value
    return out
