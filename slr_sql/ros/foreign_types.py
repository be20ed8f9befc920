"""Subscribe to (and publish) ROS 2 topics whose message package is not installed in Python.

rclpy needs a message's compiled *type support* to create a subscription, even one that only
takes serialized bytes (``raw=True``). The ROS 2 wheels have none for some packages (there is
no ``tf2_msgs`` wheel), so ``/tf`` could not be subscribed although rosbags decodes its bytes
perfectly well.

For a raw subscription or a raw publisher the middleware uses the type support for three
things only: the DDS type name (``tf2_msgs::msg::dds_::TFMessage_``, which must match the
other side's), the type hash announced on the graph, and the size bounds of the type (to
choose its buffers). :func:`stand_in_class` makes a message class whose type support is
Fast DDS's support of an installed message with the same kind of bounds (an unbounded one,
``sensor_msgs/JointState``) under the foreign type's name and RIHS01 hash (computed by
rosbags from the definition). Serialized bytes pass through unchanged; rosbags does the
decoding. Only raw use is possible: the stand-in cannot build or read message objects.

Limits: only for the Fast DDS middleware (``rmw_fastrtps_cpp``, the wheels' and ROS 2's
default); the node's type description service describes the stand-in's type with the
donor's description. Where the layout of the type support structures differs from the one
checked below, :func:`stand_in_class` returns None and the topic is reported as not
subscribable instead.

>>> stand_in_class("not a type", None) is None
True
"""
from __future__ import annotations

import ctypes
from typing import Any

__all__ = ["stand_in_class"]

_FASTRTPS_C = b"rosidl_typesupport_fastrtps_c"
_DONOR = ("sensor_msgs.msg", "JointState", b"sensor_msgs::msg")
_KEEP: list = []        # ctypes objects the C side points to: they must live as long as we do
_MADE: dict[str, Any] = {}


class _TypeSupport(ctypes.Structure):
    """rosidl_message_type_support_t (rosidl_runtime_c, ROS 2 Jazzy and later)."""

    _fields_ = [("identifier", ctypes.c_char_p), ("data", ctypes.c_void_p),
                ("func", ctypes.c_void_p), ("get_type_hash", ctypes.c_void_p),
                ("get_type_description", ctypes.c_void_p),
                ("get_type_description_sources", ctypes.c_void_p)]


class _FastCallbacks(ctypes.Structure):
    """message_type_support_callbacks_t (rosidl_typesupport_fastrtps_cpp)."""

    _fields_ = [("message_namespace", ctypes.c_char_p), ("message_name", ctypes.c_char_p),
                ("cdr_serialize", ctypes.c_void_p), ("cdr_deserialize", ctypes.c_void_p),
                ("get_serialized_size", ctypes.c_void_p), ("max_serialized_size", ctypes.c_void_p),
                ("key_callbacks", ctypes.c_void_p)]


class _TypeHash(ctypes.Structure):
    """rosidl_type_hash_t."""

    _fields_ = [("version", ctypes.c_uint8), ("value", ctypes.c_uint8 * 32)]


_HANDLE_FUNCTION = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_void_p, ctypes.c_char_p)
_HASH_FUNCTION = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_void_p)


def _capsule_api() -> Any:
    api = ctypes.pythonapi
    api.PyCapsule_GetPointer.restype = ctypes.c_void_p
    api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
    api.PyCapsule_New.restype = ctypes.py_object
    api.PyCapsule_New.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p]
    return api


def stand_in_class(msgtype: str, typestore: Any) -> Any | None:
    """A message class usable with ``create_subscription(..., raw=True)`` and for publishing
    serialized bytes on a topic of ``msgtype`` (``pkg/msg/Name``), whose definition
    ``typestore`` (a rosbags type store) knows; None when this cannot be done here.

    >>> stand_in_class("not a type", None) is None   # no pkg/msg/Name: nothing to stand in
    True
    >>> stand_in_class("robot_msgs/msg/Battery", None) is None   # a type no type store defines
    True
    """
    if msgtype in _MADE:
        return _MADE[msgtype]
    pkg, sep, name = msgtype.partition("/msg/")
    if not sep or not pkg or not name or typestore is None or msgtype not in typestore.fielddefs:
        return None
    try:
        import importlib

        donor = getattr(importlib.import_module(_DONOR[0]), _DONOR[1])
        donor.__class__.__import_type_support__()
        api = _capsule_api()
        donor_handle = api.PyCapsule_GetPointer(donor._TYPE_SUPPORT, None)
        dispatch = _TypeSupport.from_address(donor_handle)
        fast_address = _HANDLE_FUNCTION(dispatch.func)(donor_handle, _FASTRTPS_C)
        if not fast_address:
            return None
        fast = _TypeSupport.from_address(fast_address)
        callbacks = _FastCallbacks.from_address(fast.data)
        # The layout check: the donor's own names where this module expects them.
        if fast.identifier != _FASTRTPS_C or callbacks.message_namespace != _DONOR[2] \
                or callbacks.message_name != _DONOR[1].encode():
            return None
        digest = bytes.fromhex(typestore.hash_rihs01(msgtype).split("_", 1)[1])
    except (ImportError, AttributeError, ValueError, TypeError, OSError):
        return None
    ours = _FastCallbacks(f"{pkg}::msg".encode(), name.encode(), callbacks.cdr_serialize,
                          callbacks.cdr_deserialize, callbacks.get_serialized_size,
                          callbacks.max_serialized_size, None)
    type_hash = _TypeHash(1, (ctypes.c_uint8 * 32)(*digest))
    hash_function = _HASH_FUNCTION(lambda _handle: ctypes.addressof(type_hash))
    handle = _TypeSupport(_FASTRTPS_C, ctypes.addressof(ours), fast.func,
                          ctypes.cast(hash_function, ctypes.c_void_p).value,
                          fast.get_type_description, fast.get_type_description_sources)
    _KEEP.extend([ours, type_hash, hash_function, handle])
    capsule = api.PyCapsule_New(ctypes.addressof(handle), None, None)
    # rclpy reads the capsules from the message class's metaclass, as generated classes have.
    metaclass = type(f"Metaclass_{name}", (type,), {
        "_TYPE_SUPPORT": capsule,
        "_CREATE_ROS_MESSAGE": donor._CREATE_ROS_MESSAGE,
        "_CONVERT_FROM_PY": donor._CONVERT_FROM_PY,
        "_CONVERT_TO_PY": donor._CONVERT_TO_PY,
        "_DESTROY_ROS_MESSAGE": donor._DESTROY_ROS_MESSAGE,
        "__import_type_support__": classmethod(lambda cls: None),
    })
    cls = metaclass(name, (), {"__doc__": f"Raw-only stand-in for {msgtype}.",
                               "__msgtype__": msgtype})
    _MADE[msgtype] = cls
    return cls
