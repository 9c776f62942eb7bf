# The running Blender's OpenImageDenoise, for the engine's Denoise option. Official Blender builds load Intel's
# OpenImageDenoise library (Cycles' and the compositor's denoiser) when they start; a build without it (Debian's
# Blender 3.4) has none, and the option then says so instead of denoising. Nothing is bundled: the library the process
# already holds is used, through its C API (OpenImageDenoise 2.x, include/OpenImageDenoise/oidn.h).
import ctypes
import os
import sys

import numpy as np

# The library's names: the soname on Linux, the DLL beside blender.exe on Windows.
_LIBRARY = "OpenImageDenoise.dll" if sys.platform == "win32" else "libOpenImageDenoise.so.2"
_DEVICE_CPU = 1    # OIDN_DEVICE_TYPE_CPU
_FORMAT_FLOAT3 = 3  # OIDN_FORMAT_FLOAT3

UNAVAILABLE = ("this Blender has no OpenImageDenoise (official Blender builds have it; Debian's does not): "
               "the image is not denoised")

_library = None
_looked = False


def _loaded_library():
    """The OpenImageDenoise library this process has already loaded, or None. Only a library Blender itself loaded
    counts: loading one found elsewhere could mix two versions of it in one process."""
    if sys.platform == "win32":
        handle = ctypes.windll.kernel32.GetModuleHandleW(_LIBRARY)
        return ctypes.CDLL(_LIBRARY, handle=handle) if handle else None
    try:
        return ctypes.CDLL(_LIBRARY, mode=os.RTLD_NOLOAD | os.RTLD_NOW)
    except OSError:
        return None


def _declare(lib):
    p, s = ctypes.c_void_p, ctypes.c_size_t
    signatures = {
        "oidnNewDevice": (p, [ctypes.c_int]),
        "oidnCommitDevice": (None, [p]),
        "oidnReleaseDevice": (None, [p]),
        "oidnGetDeviceError": (ctypes.c_int, [p, ctypes.POINTER(ctypes.c_char_p)]),
        "oidnNewFilter": (p, [p, ctypes.c_char_p]),
        "oidnSetSharedFilterImage": (None, [p, ctypes.c_char_p, p, ctypes.c_int, s, s, s, s, s]),
        "oidnSetFilterBool": (None, [p, ctypes.c_char_p, ctypes.c_bool]),
        "oidnCommitFilter": (None, [p]),
        "oidnExecuteFilter": (None, [p]),
        "oidnReleaseFilter": (None, [p]),
    }
    for name, (restype, argtypes) in signatures.items():
        function = getattr(lib, name)
        function.restype, function.argtypes = restype, argtypes
    return lib


def library():
    """The declared library, or None when this Blender has none (looked up once)."""
    global _library, _looked
    if not _looked:
        _looked = True
        lib = _loaded_library()
        try:
            _library = _declare(lib) if lib is not None else None
        except AttributeError:  # a library without the 2.x API
            _library = None
    return _library


def available():
    return library() is not None


def _image(values):
    """A C-contiguous float32 (h, w, 3) copy or view of `values`."""
    return np.ascontiguousarray(values[..., :3], dtype=np.float32)


def denoise(color, albedo=None, normal=None):
    """`color` (h, w, 3 or more: the first three are linear RGB, high dynamic range) denoised by OpenImageDenoise's
    ray-tracing filter, as a new (h, w, 3) float32 array. `albedo` and `normal` (h, w, 3), both or neither, guide it.
    Raises RuntimeError when this Blender has no OpenImageDenoise or the denoiser reports an error."""
    lib = library()
    if lib is None:
        raise RuntimeError(UNAVAILABLE)
    if (albedo is None) != (normal is None):
        raise ValueError("denoise: albedo and normal guide together (the denoiser takes the normal only with the "
                         "albedo)")
    images = {"color": _image(color)}
    if albedo is not None:
        images.update(albedo=_image(albedo), normal=_image(normal))
    height, width = images["color"].shape[:2]
    output = np.empty((height, width, 3), dtype=np.float32)
    device = lib.oidnNewDevice(_DEVICE_CPU)
    if not device:
        raise RuntimeError("OpenImageDenoise could not make a CPU device")
    denoiser = None
    try:
        lib.oidnCommitDevice(device)
        denoiser = lib.oidnNewFilter(device, b"RT")
        for name, array in (*images.items(), ("output", output)):
            lib.oidnSetSharedFilterImage(denoiser, name.encode(), array.ctypes.data, _FORMAT_FLOAT3, width, height,
                                         0, 0, 0)
        lib.oidnSetFilterBool(denoiser, b"hdr", True)
        lib.oidnCommitFilter(denoiser)
        lib.oidnExecuteFilter(denoiser)
        message = ctypes.c_char_p()
        if lib.oidnGetDeviceError(device, ctypes.byref(message)) != 0:
            raise RuntimeError("OpenImageDenoise: " + (message.value or b"unknown error").decode(errors="replace"))
    finally:
        if denoiser:
            lib.oidnReleaseFilter(denoiser)
        lib.oidnReleaseDevice(device)
    return output
