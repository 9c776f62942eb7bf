# The splat formats, as the core's format table gives them (splat_formats(), match_splat_format()): the one source of
# every list of formats, extensions and file-browser filters the add-on shows.
from .. import native



def splat_formats(writable_only=False):
    """The splat formats the core reads (and, where "writable", writes), from the core (the one list of them): dicts of
    name, extensions (endings of file names: ".ply", or a whole name such as SOG's "meta.json"; the first is the one
    written), description, up_axis (of the cloud as read: -Y) and writable. `writable_only`: the ones export offers."""
    formats = native.core().splat_formats()
    return [f for f in formats if f.get("writable", True)] if writable_only else formats


def splat_format_of(filepath, writable_only=False):
    """The core's entry for the format the file's name ends with (the core's match_splat_format: the longest ending
    that matches, so "a.compressed.ply" is a compressed PLY, "a.ply" an INRIA one), or None."""
    match = native.core().match_splat_format(filepath, writable_only)
    return None if match is None else next(f for f in splat_formats() if f["name"] == match["name"])


def with_splat_extension(filepath, extension):
    """`filepath` ending in `extension`: the ending of a format the core writes (the whole ".compressed.ply") is
    replaced, anything else kept and the extension added."""
    match = native.core().match_splat_format(filepath, True)
    return filepath[:len(filepath) - len(match["ending"])] + extension if match else filepath + extension


def writable_splat_formats():
    """The entries of splat_formats() the core also writes (not glTF, written by the mesh export, nor SOG)."""
    return splat_formats(writable_only=True)


def splat_extensions(writable_only=False):
    return tuple(extension for f in splat_formats(writable_only) for extension in f["extensions"])


def splat_file_browser_filter(writable_only=False):
    """The file browser's filter_glob for splat files: "*.ply;*.splat;*.spz;…;*meta.json"."""
    return ";".join("*" + extension for extension in splat_extensions(writable_only))


def open_splat_file_browser(operator, helper, context, event, writable_only=False):
    """The invoke() of a splat import/export operator: the file browser (ImportHelper's or ExportHelper's)
    filtered to the core's formats (export: `writable_only`); without the native module, the error instead."""
    try:
        operator.filter_glob = splat_file_browser_filter(writable_only)
    except native.NativeModuleMissing as error:
        operator.report({"ERROR"}, str(error))
        return {"CANCELLED"}
    return helper.invoke(operator, context, event)


def splat_menu_text(writable_only=False):
    """ "Gaussian Splats (.ply/.splat/.spz/.sog/meta.json)", or without the list when the native module is missing."""
    try:
        return f"Gaussian Splats ({'/'.join(splat_extensions(writable_only))})"
    except native.NativeModuleMissing:
        return "Gaussian Splats"
