"""Taking a subscription's messages as CDR bytes together with their publisher's GID.

Jazzy's rclpy hands a subscription callback no publisher GID (its message info
has timestamps and sequence numbers only, and a two-argument callback fails
under the EventsExecutor), yet the GID is what tells a robot's real host from a
stranger publishing on the same topic. So a process's robot subscriptions are
not spun by an executor: the transport polls them here, calling librcl's
`rcl_take_serialized_message` through ctypes on the rcl handle rclpy already
made, which fills `rmw_message_info_t.publisher_gid`. The bytes are then
decoded with rclpy's own serialization.

The struct layouts are those of rmw 7.3 and rcutils 6.7 (Jazzy's
`rmw/types.h`, `rcutils/allocator.h`, `rcutils/types/uint8_array.h`); the
first 12 bytes of a Fast DDS GID are the GUID prefix of the writer's
participant, the same for every writer of one process.
"""

from __future__ import annotations

import ctypes
import os
import sys
from pathlib import Path

import rclpy

from camo_core.exceptions import EXIT_USAGE
from camo_core.inputs.files import shown

RMW_GID_STORAGE_SIZE = 16
RCL_RET_OK = 0
RCL_RET_SUBSCRIPTION_TAKE_FAILED = 401
PREFIX = 12  # bytes of a GID that name the writer's participant (its process)


class RcutilsAllocator(ctypes.Structure):
    _fields_ = [
        ("allocate", ctypes.c_void_p),
        ("deallocate", ctypes.c_void_p),
        ("reallocate", ctypes.c_void_p),
        ("zero_allocate", ctypes.c_void_p),
        ("state", ctypes.c_void_p),
    ]


class SerializedMessage(ctypes.Structure):  # rmw_serialized_message_t == rcutils_uint8_array_t
    _fields_ = [
        ("buffer", ctypes.POINTER(ctypes.c_uint8)),
        ("buffer_length", ctypes.c_size_t),
        ("buffer_capacity", ctypes.c_size_t),
        ("allocator", RcutilsAllocator),
    ]


class Gid(ctypes.Structure):
    _fields_ = [
        ("implementation_identifier", ctypes.c_char_p),
        ("data", ctypes.c_uint8 * RMW_GID_STORAGE_SIZE),
    ]


class MessageInfo(ctypes.Structure):
    _fields_ = [
        ("source_timestamp", ctypes.c_int64),
        ("received_timestamp", ctypes.c_int64),
        ("publication_sequence_number", ctypes.c_uint64),
        ("reception_sequence_number", ctypes.c_uint64),
        ("publisher_gid", Gid),
        ("from_intra_process", ctypes.c_bool),
    ]


def _libraries() -> tuple[ctypes.CDLL, ctypes.CDLL, ctypes.CDLL]:
    """librcutils, librcl and the Fast DDS rmw: the very files rclpy's extension loaded."""
    folder = Path(rclpy.__file__).resolve().parents[3]  # <venv>/lib/python3.X/site-packages/rclpy
    override = os.environ.get("CAMO_RCL_LIB")  # a folder of one's own build of them
    lib = Path(override) if override else folder
    try:
        return tuple(
            ctypes.CDLL(str(lib / name))
            for name in ("librcutils.so", "librcl.so", "librmw_fastrtps_cpp.so")
        )
    except OSError as exc:
        if not override:
            raise  # the venv's own files: a broken installation, not a bad input
        # At import, before any entry point's error handling: one line and exit 2 here.
        detail = str(exc).splitlines()[0] if str(exc) else "cannot load"
        print(f"camo: error: CAMO_RCL_LIB={shown(override)!r}: {shown(detail)}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None


_rcutils, _rcl, _rmw = _libraries()
_rcutils.rcutils_get_default_allocator.restype = RcutilsAllocator
_rcutils.rcutils_get_default_allocator.argtypes = []
_rcutils.rcutils_uint8_array_init.restype = ctypes.c_int
_rcutils.rcutils_uint8_array_init.argtypes = [
    ctypes.POINTER(SerializedMessage),
    ctypes.c_size_t,
    ctypes.POINTER(RcutilsAllocator),
]
_rcutils.rcutils_uint8_array_fini.restype = ctypes.c_int
_rcutils.rcutils_uint8_array_fini.argtypes = [ctypes.POINTER(SerializedMessage)]
_rcutils.rcutils_reset_error.restype = None
_rcl.rcl_take_serialized_message.restype = ctypes.c_int
_rcl.rcl_take_serialized_message.argtypes = [
    ctypes.c_void_p,
    ctypes.POINTER(SerializedMessage),
    ctypes.POINTER(MessageInfo),
    ctypes.c_void_p,
]
_rcl.rcl_publisher_get_rmw_handle.restype = ctypes.c_void_p
_rcl.rcl_publisher_get_rmw_handle.argtypes = [ctypes.c_void_p]
_rmw.rmw_get_gid_for_publisher.restype = ctypes.c_int
_rmw.rmw_get_gid_for_publisher.argtypes = [ctypes.c_void_p, ctypes.POINTER(Gid)]


class TakeError(RuntimeError):
    pass


class Taker:
    """Polls one rclpy Subscription, whose node no executor spins (or both would take)."""

    def __init__(self, subscription, capacity: int = 512) -> None:
        self.subscription = subscription  # keeps the rcl handle alive while we use it
        self._handle = ctypes.c_void_p(subscription.handle.pointer)
        self._allocator = _rcutils.rcutils_get_default_allocator()
        self._message = SerializedMessage()
        self._info = MessageInfo()
        if _rcutils.rcutils_uint8_array_init(
            ctypes.byref(self._message), capacity, ctypes.byref(self._allocator)
        ):
            raise TakeError("cannot allocate a serialized message buffer")
        self._message_ref = ctypes.byref(self._message)
        self._info_ref = ctypes.byref(self._info)
        self.closed = False

    def take(self, out: list[tuple[bytes, bytes]], limit: int) -> int:
        """Append (CDR bytes, publisher GID) of at most `limit` waiting messages to `out`; how
        many. Bounded: messages can arrive faster than they are taken, and a caller that took
        "everything waiting" would never get back to its stop flag and timers."""
        if self.closed:
            return 0
        take, handle = _rcl.rcl_take_serialized_message, self._handle
        message, gid = self._message, self._info.publisher_gid.data
        count = 0
        while count < limit:
            ret = take(handle, self._message_ref, self._info_ref, None)
            if ret != RCL_RET_OK:
                if ret != RCL_RET_SUBSCRIPTION_TAKE_FAILED:
                    _rcutils.rcutils_reset_error()
                    raise TakeError(f"rcl_take_serialized_message returned {ret}")
                return count
            out.append((ctypes.string_at(message.buffer, message.buffer_length), bytes(gid)))
            count += 1
        return count

    def close(self) -> None:
        """Before the subscription is destroyed: taking from a destroyed one crashes."""
        if not self.closed:
            self.closed = True
            _rcutils.rcutils_uint8_array_fini(ctypes.byref(self._message))


def publisher_gid(publisher) -> bytes:
    """The 16-byte GID of one of our own rclpy Publishers (as takers see it)."""
    handle = _rcl.rcl_publisher_get_rmw_handle(ctypes.c_void_p(publisher.handle.pointer))
    gid = Gid()
    if _rmw.rmw_get_gid_for_publisher(ctypes.c_void_p(handle), ctypes.byref(gid)):
        _rcutils.rcutils_reset_error()
        raise TakeError("rmw_get_gid_for_publisher failed")
    return bytes(gid.data)
