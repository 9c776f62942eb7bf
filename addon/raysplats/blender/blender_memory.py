# Reads of Blender's memory at addresses the add-on worked out itself (as_pointer() plus an offset, a pointer inside
# one of bmesh's Python objects), made so that a wrong address gives an error, never a crash.
#
# The rule every fast path that reads or writes Blender's arrays or structs in place follows: first read a few values
# through these functions and compare them with what Blender's Python API reports for the same elements; only when they
# agree is the memory touched directly (a ctypes or numpy view, the native core). A layout that a new Blender changed
# then costs speed (the Python API path), not Blender.
#
# How: on Linux through /proc/self/mem, whose reads the kernel checks page by page (an unmapped address fails with
# EIO). Where there is no /proc (Windows, macOS) nothing can be read safely: available() is False and every fast path
# takes the Python API. RAYSPLATS_DISTRUST_BLENDER_MEMORY=1 makes it False anywhere (to compare the two paths).
import os
import struct
import sys

DISTRUST_VARIABLE = "RAYSPLATS_DISTRUST_BLENDER_MEMORY"


class MemoryUnreadable(Exception):
    """An address that cannot be read (not mapped, out of range), or no safe way to read on this system."""


_mem_fd = None  # the open /proc/self/mem, once it passed its self-test
_opened = False  # (tried to open it: do not try again)
_warned = set()


def _open():
    global _mem_fd, _opened
    _opened = True
    if sys.platform != "linux" or not hasattr(os, "pread"):
        return
    try:
        import ctypes
        fd = os.open("/proc/self/mem", os.O_RDONLY)
    except (OSError, ImportError):
        return
    # Self-test: a buffer of known bytes must read back as themselves.
    known = ctypes.create_string_buffer(b"RaySplats memory probe\x00\xff")
    try:
        ok = os.pread(fd, len(known.raw), ctypes.addressof(known)) == known.raw
    except (OSError, OverflowError, ValueError):
        ok = False
    if ok:
        _mem_fd = fd
    else:
        os.close(fd)


def available():
    """True when this process can read its own memory safely (and the user has not said otherwise)."""
    if os.environ.get(DISTRUST_VARIABLE, "") not in ("", "0"):
        return False
    if not _opened:
        _open()
    return _mem_fd is not None


def read(address, size):
    """`size` bytes of this process's memory at `address`; MemoryUnreadable when any of them cannot be read."""
    if not available():
        raise MemoryUnreadable("no safe way to read this process's memory here")
    if address <= 0 or size < 0:
        raise MemoryUnreadable(f"address {address:#x} cannot be read")
    try:
        data = os.pread(_mem_fd, size, address)
    except (OSError, OverflowError, ValueError) as error:
        raise MemoryUnreadable(f"address {address:#x} cannot be read: {error}") from None
    if len(data) != size:
        raise MemoryUnreadable(f"only {len(data)} of {size} bytes at {address:#x} can be read")
    return data


def pointer_at(address):
    """The pointer (64-bit) stored at `address` (0 for a null pointer)."""
    return struct.unpack("<Q", read(address, 8))[0]


def int_at(address):
    """The C int (32-bit, signed) stored at `address`."""
    return struct.unpack("<i", read(address, 4))[0]


def uint32_at(address):
    return struct.unpack("<I", read(address, 4))[0]


def byte_at(address):
    return read(address, 1)[0]


def floats_at(address, count):
    """`count` C floats stored from `address`, as a tuple of Python floats."""
    return struct.unpack(f"<{count}f", read(address, 4 * count))


def _warn_once(key, message):
    if key in _warned:
        return
    _warned.add(key)
    print(f"RaySplats: warning: {message}", file=sys.stderr, flush=True)


def warn_fallback(what, layout_differs):
    """The one warning that a fast path is off for the session and the Python API reads instead: per `what` (e.g.
    "Reading Edit Mode meshes") when Blender's layout differs from the expected one (`layout_differs` says how), or a
    single one for every fast path when memory cannot be read safely here at all."""
    if available():
        _warn_once(what, f"{what} goes through Blender's Python API (slower): {layout_differs}")
    elif os.environ.get(DISTRUST_VARIABLE, "") not in ("", "0"):
        _warn_once(None, f"Blender's arrays are read through its Python API (slower): {DISTRUST_VARIABLE} is set")
    else:
        _warn_once(None, "Blender's arrays are read through its Python API (slower): this system has no safe way to "
                         "read Blender's memory (/proc/self/mem)")
