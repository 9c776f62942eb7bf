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
    The guides are denoised first and then given to the colour's filter as clean (OpenImageDenoise's two-pass
    workflow for noisy auxiliary images, Cycles' Prefilter "Accurate", its default): a guide averaged over few
    samples carries their aliasing, which the filter would otherwise keep in the colour as texture.
    Raises RuntimeError when this Blender has no OpenImageDenoise or the denoiser reports an error."""
    lib = library()
    if lib is None:
        raise RuntimeError(UNAVAILABLE)
    if (albedo is None) != (normal is None):
        raise ValueError("denoise: albedo and normal guide together (the denoiser takes the normal only with the "
                         "albedo)")
    color = _image(color)
    height, width = color.shape[:2]
    output = np.empty((height, width, 3), dtype=np.float32)
    device = lib.oidnNewDevice(_DEVICE_CPU)
    if not device:
        raise RuntimeError("OpenImageDenoise could not make a CPU device")
    try:
        lib.oidnCommitDevice(device)
        if albedo is None:
            _filter(lib, device, {"color": color}, output, width, height, hdr=True)
        else:
            # Copies: the guides are denoised in place.
            albedo, normal = np.array(_image(albedo)), np.array(_image(normal))
            _filter(lib, device, {"albedo": albedo}, albedo, width, height)
            _filter(lib, device, {"normal": normal}, normal, width, height)
            _filter(lib, device, {"color": color, "albedo": albedo, "normal": normal}, output, width, height,
                    hdr=True, clean_aux=True)
    finally:
        lib.oidnReleaseDevice(device)
    return output


def _filter(lib, device, images, output, width, height, hdr=False, clean_aux=False):
    """One run of the "RT" filter on `device` over `images` (name: (h, w, 3) float32) into `output`. With only an
    albedo or a normal image it denoises that image (OpenImageDenoise's prefiltering of auxiliary images)."""
    denoiser = lib.oidnNewFilter(device, b"RT")
    try:
        for name, array in (*images.items(), ("output", output)):
            lib.oidnSetSharedFilterImage(denoiser, name.encode(), array.ctypes.data, _FORMAT_FLOAT3, width, height,
                                         0, 0, 0)
        if hdr:
            lib.oidnSetFilterBool(denoiser, b"hdr", True)
        if clean_aux:
            lib.oidnSetFilterBool(denoiser, b"cleanAux", True)
        lib.oidnCommitFilter(denoiser)
        lib.oidnExecuteFilter(denoiser)
        message = ctypes.c_char_p()
        if lib.oidnGetDeviceError(device, ctypes.byref(message)) != 0:
            raise RuntimeError("OpenImageDenoise: " + (message.value or b"unknown error").decode(errors="replace"))
    finally:
        if denoiser:
            lib.oidnReleaseFilter(denoiser)
