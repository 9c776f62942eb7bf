# Lazy access to the native core, so that the add-on still registers (and says what is missing) when the
# module has not been built, as the glTF add-on does for Draco.
# The package may hold one module per Python ABI (the extension zips carry _native.cpython-311-*.so or
# _native.cp311-win_amd64.pyd for Blender 4.2 to 5.0, and the 313 ones for 5.1+); `from . import _native` takes the one whose tag is this Python's
# (importlib.machinery.EXTENSION_SUFFIXES), so no choice is made here.
import glob
import importlib.machinery
import os
import sys

_module = None


class NativeModuleMissing(RuntimeError):
    pass


def core():
    """Returns raysplats._native, or raises NativeModuleMissing with instructions."""
    global _module
    if _module is None:
        try:
            from . import _native
        except ImportError as error:
            folder = os.path.dirname(os.path.abspath(__file__))
            present = sorted(os.path.basename(path) for pattern in ("_native*.so", "_native*.pyd")
                             for path in glob.glob(os.path.join(folder, pattern)))
            wanted = "_native" + importlib.machinery.EXTENSION_SUFFIXES[0]
            raise NativeModuleMissing(
                f"The RaySplats native module for this Blender's Python {sys.version_info.major}."
                f"{sys.version_info.minor} ({wanted}) is missing or does not load ({error}); the add-on has "
                f"{', '.join(present) or 'no native module'}. Install the extension zip made for your Blender, or "
                "build the module with scripts/build.sh (see README)."
            ) from error
        _module = _native
    return _module


def is_available():
    try:
        core()
        return True
    except NativeModuleMissing:
        return False
