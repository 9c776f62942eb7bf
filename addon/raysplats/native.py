# Lazy access to the native core, so that the add-on still registers (and says what is missing) when the
# module has not been built, as the glTF add-on does for Draco.
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
            raise NativeModuleMissing(
                "The RaySplats native module is not built or does not match this Blender's Python "
                f"({error}). Build it with scripts/build.sh (see README)."
            ) from error
        _module = _native
    return _module


def is_available():
    try:
        core()
        return True
    except NativeModuleMissing:
        return False
