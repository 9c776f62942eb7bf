# RaySplats command line for pipelines, run inside Blender:
#
#   blender -b [file.blend] --python addon/raysplats/cli.py -- <command> [options] INPUT... -o OUTPUT
#
# (with the add-on installed, the same file is <user scripts>/addons/raysplats/cli.py; `--python-expr
# "import raysplats.cli as c; c.main()"` works too). Commands:
#
#   import  SPLATS... -o DIR|FILE.blend    splat file(s) -> .blend, one Gaussian object each
#   export  INPUTS... -o DIR|FILE --format glb|gltf|obj|ply [--draco] [...]
#                                          .blend or splat file(s) -> OBJ / PLY / glTF / GLB (Draco on request)
#   render  INPUTS... -o DIR|FILE.png [--resolution W H] [--samples N]
#                                          .blend or splat file(s) -> image (RaySplats engine if present, else
#                                          Cycles CPU); splat files and cameraless scenes get a framing camera
#   convert SPLATS... -o DIR|FILE --format FORMAT
#                                          splat file(s) -> splat file(s) (the formats the core writes)
#
# SPLATS are files of any format the core reads (`--help` lists them and the formats convert writes, from the core's
# format table).
#
# INPUT may be a glob ("scans/*.ply", quoted or expanded by the shell); with several inputs OUTPUT is a folder
# and each output is named after its input. With no INPUT, the .blend Blender opened is the input. One progress
# line per file; a file that fails is reported and skipped, the others still written. Every output is written
# to a temporary file and renamed, so nothing is half-written. Exit status: 0 all done, 1 some file failed,
# 2 bad command line.
import argparse
import contextlib
import glob
import os
import sys
import time
import traceback

import bpy

# Imported as a module of an installed extension (bl_ext.<repository>.raysplats.cli, Blender 4.2+: how a farm job runs
# it, farm/openjd/raysplats_convert.yaml), the add-on is not importable as `raysplats`, the name the functions below
# import it by: give it and each of its modules (its __init__ imports them all) that name, so that no second copy of
# any is loaded.
if __package__ and __package__ != "raysplats" and __package__.endswith(".raysplats"):
    for _name, _module in list(sys.modules.items()):
        if _name == __package__ or _name.startswith(__package__ + "."):
            sys.modules.setdefault("raysplats" + _name[len(__package__):], _module)


# Format names and extensions come from the add-on (which takes the splat formats from the core); it is
# imported only once ensure_addon() has registered it.
def _splat_formats():
    """The formats a splat file can be converted to (the core writes them)."""
    from raysplats.io import format_table
    return tuple(f["name"] for f in format_table.splat_formats(writable_only=True))


def _splat_extensions(writable_only=False):
    from raysplats.io import format_table
    return format_table.splat_extensions(writable_only)


def _is_splat_file(path):
    """Whether the name ends in one of the core's splat endings (the core's rule, format_table.splat_format_of)."""
    from raysplats.io import format_table
    return format_table.splat_format_of(path) is not None


def _mesh_formats():
    from raysplats.io import export_mesh
    return tuple(sorted(extension.lstrip(".") for extension in export_mesh.MESH_EXTENSIONS))


class UsageError(Exception):
    pass


_registered_here = None  # the add-on package when this script registered it (unregistered again at the end)


def ensure_addon():
    """Registers the add-on this file belongs to (the source tree's, or the installed copy's), unless Blender
    already has a RaySplats add-on enabled."""
    if hasattr(bpy.types.Object, "raysplats"):
        return
    package_dir = os.path.dirname(os.path.abspath(__file__))
    loaded = sys.modules.get("raysplats")
    if loaded is None or os.path.dirname(os.path.abspath(loaded.__file__)) != package_dir:
        for name in [m for m in sys.modules if m == "raysplats" or m.startswith("raysplats.")]:
            del sys.modules[name]
        sys.path.insert(0, os.path.dirname(package_dir))
    import raysplats
    raysplats.register()
    global _registered_here
    _registered_here = raysplats


def _parser():
    parser = argparse.ArgumentParser(prog="blender -b [file.blend] --python cli.py --",
                                     description="RaySplats batch import / export / render / convert")
    commands = parser.add_subparsers(dest="command", required=True)

    def common(sub):
        sub.add_argument("inputs", nargs="*", help="input files or globs (none: the .blend Blender opened)")
        sub.add_argument("-o", "--output", required=True, help="output folder, or a file for a single input")
        sub.add_argument("--vertices-per-polygon", type=int, default=0,
                         help="K for splat inputs (default 0: Auto, 8 up to 1 M Gaussians, 4 above)")
        sub.add_argument("--radius", type=float, default=3.0, help="rho for splat inputs (default 3)")
        sub.add_argument("--up-axis", default="DETECT", choices=("DETECT", "AUTO", "-Y", "Y", "Z", "-Z", "X", "-X"),
                         help="up axis of splat inputs (default DETECT: found from the data, else by format; "
                              "AUTO: by format)")
        return sub

    common(commands.add_parser("import", help=f"splat files ({', '.join(_splat_extensions())}) -> .blend"))
    export = common(commands.add_parser("export", help=".blend or splat files -> OBJ/PLY/glTF/GLB"))
    export.add_argument("--format", choices=_mesh_formats(), help="output format (default: the output file's extension)")
    export.add_argument("--draco", action="store_true", help="Draco-compress glTF/GLB meshes")
    export.add_argument("--draco-position-bits", type=int, default=14)
    export.add_argument("--draco-normal-bits", type=int, default=10)
    export.add_argument("--draco-uv-bits", type=int, default=12)
    export.add_argument("--draco-compression-level", type=int, default=7)
    export.add_argument("--polygons", action="store_true", help="export the Gaussians' polygons, not splat patches")
    export.add_argument("--local", action="store_true", help="local coordinates (glTF nodes carry the transforms)")
    export.add_argument("--mesh-up-axis", default="Y", choices=("Y", "Z"), help="OBJ/PLY up axis (glTF: always Y)")
    export.add_argument("--gaussian-splatting", action="store_true", help="also write KHR_gaussian_splatting points")
    export.add_argument("--no-modifiers", action="store_true", help="export without applying modifiers")
    render = common(commands.add_parser("render", help=".blend or splat files -> PNG"))
    render.add_argument("--resolution", type=int, nargs=2, default=(640, 480), metavar=("W", "H"))
    render.add_argument("--samples", type=int, default=16)
    convert = commands.add_parser("convert", help=f"splat files -> splat files ({', '.join(_splat_extensions(True))})")
    convert.add_argument("inputs", nargs="+", help=f"splat files ({', '.join(_splat_extensions())}) or globs")
    convert.add_argument("-o", "--output", required=True, help="output folder, or a file for a single input")
    convert.add_argument("--format", choices=_splat_formats(), help="output format (default: the output's extension)")
    return parser


def _expand(patterns):
    files = []
    for pattern in patterns:
        matches = sorted(glob.glob(pattern)) if glob.has_magic(pattern) else [pattern]
        if not matches:
            raise UsageError(f"no file matches '{pattern}'")
        files.extend(matches)
    return files


def _output_path(args, source, extension, count):
    """The output file for one input: args.output itself for a single input with a file name, else
    <args.output>/<input stem><extension>."""
    output = args.output
    if count == 1 and os.path.splitext(output)[1] and not os.path.isdir(output):
        if not output.lower().endswith(extension):
            raise UsageError(f"output '{output}' does not end in {extension}")
        return output
    os.makedirs(output, exist_ok=True)
    return os.path.join(output, os.path.splitext(os.path.basename(source))[0] + extension)


@contextlib.contextmanager
def _atomic_output(path):
    """Yields a temporary path beside `path`; renames it over `path` if the block succeeds, removes it
    otherwise, so a failed command never leaves a half-written output."""
    stem, extension = os.path.splitext(path)
    temporary = f"{stem}.tmp{os.getpid()}{extension}"
    try:
        yield temporary
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.remove(temporary)


def _import_splats(source, args):
    from raysplats.io import import_splats
    obj, warnings, _ = import_splats.import_gaussian_splats(
        bpy.context, source, vertices_per_polygon=args.vertices_per_polygon, radius=args.radius,
        up_axis=args.up_axis)
    for warning in warnings:
        print(f"  warning: {warning}")
    return obj


def _open_input(source, args):
    if source.lower().endswith(".blend"):
        bpy.ops.wm.open_mainfile(filepath=source)
        ensure_addon()
    else:
        if not _is_splat_file(source):
            raise ValueError(f"'{source}': not a .blend or splat file ({', '.join(_splat_extensions())})")
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ensure_addon()
        _import_splats(source, args)


def _do_import(source, target, args):
    if not _is_splat_file(source):
        raise ValueError(f"'{source}': not a splat file ({', '.join(_splat_extensions())})")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_addon()
    obj = _import_splats(source, args)
    with _atomic_output(target) as temporary:
        bpy.ops.wm.save_as_mainfile(filepath=temporary, copy=True, compress=False)
    from raysplats.objects import polygon_mesh
    pieces = polygon_mesh.scene_pieces(obj)
    count = sum(len(piece.data.polygons) for piece in pieces) if pieces else len(getattr(obj.data, "points", obj.data.vertices))
    return f"{count:,} Gaussians" + (f" in {len(pieces)} pieces" if len(pieces) > 1 else "")


def _do_export(source, target, args):
    from raysplats.io import export_mesh
    _open_input(source, args)
    # The native writer is atomic itself (temporary file renamed over the target).
    stats = export_mesh.export_mesh_file(
        bpy.context, target, apply_modifiers=not args.no_modifiers, coordinates="LOCAL" if args.local else "WORLD",
        up_axis=args.mesh_up_axis, splat_geometry="POLYGONS" if args.polygons else "PATCHES", draco=args.draco,
        draco_position_bits=args.draco_position_bits, draco_normal_bits=args.draco_normal_bits,
        draco_uv_bits=args.draco_uv_bits, draco_compression_level=args.draco_compression_level,
        gaussian_splatting=args.gaussian_splatting)
    return f"{stats['objects']} objects, {stats['triangles']:,} triangles, {stats['bytes'] / 1e6:.1f} MB"


def frame_camera(scene, distance=1.1, elevation=0.35):
    """A camera looking at the bulk of the scene's mesh vertices (5th-95th percentile box, robust to floaters),
    `distance` and `elevation` times the box's diagonal away from its centre (along -Y and +Z)."""
    import mathutils
    import numpy as np
    from raysplats.objects import polygon_mesh
    points = []
    for obj in scene.objects:
        if obj.type == "MESH" and len(obj.data.vertices):
            co = np.empty(len(obj.data.vertices) * 3, dtype=np.float32)
            polygon_mesh.read_vertex_positions(obj.data, co)  # 0.2 s less per 1.5 M splats on 4.x
            world = np.array(obj.matrix_world)
            points.append(co.reshape(-1, 3) @ world[:3, :3].T + world[:3, 3])
    if not points:
        raise ValueError("nothing to render: the scene has no meshes and no camera")
    points = np.concatenate(points)
    low, high = np.percentile(points, 5, axis=0), np.percentile(points, 95, axis=0)
    centre, size = (low + high) / 2, max(float(np.linalg.norm(high - low)), 1e-3)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = centre + np.array([0.0, -distance * size, elevation * size])
    direction = mathutils.Vector(centre) - camera.location
    camera.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    camera.data.clip_start, camera.data.clip_end = size * 1e-3, size * 100
    scene.camera = camera


def setup_render(scene, resolution, samples):
    """The RaySplats engine when it is registered, else Cycles on the CPU (denoising off: Debian's Blender
    has no OpenImageDenoise), as examples/demo.py does. Returns the engine's name."""
    # getattr: Blender 4.x lists base classes without bl_idname (HydraRenderEngine) among the subclasses.
    engines = {getattr(engine, "bl_idname", None) for engine in bpy.types.RenderEngine.__subclasses__()}
    scene.render.engine = "RAYSPLATS" if "RAYSPLATS" in engines else "CYCLES"
    if scene.render.engine == "RAYSPLATS":
        scene.raysplats.samples = samples
    else:
        scene.cycles.samples = samples
        scene.cycles.transparent_max_bounces = 64
        scene.cycles.device = "CPU"
        scene.cycles.use_denoising = False
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
        scene.world.color = (0.05, 0.05, 0.05)
    return scene.render.engine


def _do_render(source, target, args):
    _open_input(source, args)
    scene = bpy.context.scene
    if scene.camera is None:
        frame_camera(scene)
    engine = setup_render(scene, args.resolution, args.samples)
    scene.render.use_file_extension = False
    with _atomic_output(target) as temporary:
        scene.render.filepath = temporary
        bpy.ops.render.render(write_still=True)
        if not os.path.exists(temporary):
            raise RuntimeError(f"{engine} wrote no image")
    return f"{engine}, {args.resolution[0]}x{args.resolution[1]}"


def _do_convert(source, target, args):
    ensure_addon()
    from raysplats import native
    core = native.core()
    cloud = core.read_splats(source)
    core.write_splats(target, cloud["positions"], cloud["rotations"], cloud["scales"], cloud["opacities"], cloud["sh"])
    return f"{len(cloud['opacities']):,} Gaussians"


def run(argv):
    args = _parser().parse_args(argv)
    args.output = os.path.abspath(args.output)
    inputs = [os.path.abspath(path) for path in _expand(args.inputs)]
    if not inputs:
        if args.command in ("export", "render") and bpy.data.filepath:
            inputs = [bpy.data.filepath]
        else:
            raise UsageError("no input files (and no .blend opened)")
    if args.command == "import":
        extension = ".blend"
    elif args.command == "render":
        extension = ".png"
    elif args.command == "convert":
        # Splat formats by the core's table: "compressed_ply" is written as ".compressed.ply".
        from raysplats.io import format_table
        named = format_table.splat_format_of(args.output)
        fmt = args.format or (named["name"] if named else "")
        entry = next((f for f in format_table.splat_formats() if f["name"] == fmt), None)
        if entry is None:
            raise UsageError(f"convert: give --format ({', '.join(_splat_formats())}) or an output file with that "
                             f"format's extension ({', '.join(_splat_extensions())})")
        extension = entry["extensions"][0]
    else:
        fmt = args.format or os.path.splitext(args.output)[1].lower().lstrip(".")
        choices = _mesh_formats()
        if fmt not in choices:
            raise UsageError(f"{args.command}: give --format ({', '.join(choices)}) or an output file with that extension")
        extension = "." + fmt
    targets = [_output_path(args, source, extension, len(inputs)) for source in inputs]
    if len(set(targets)) != len(targets):
        raise UsageError("several inputs would write the same output file (same name in different folders)")
    action = {"import": _do_import, "export": _do_export, "render": _do_render, "convert": _do_convert}[args.command]

    failures = 0
    for number, (source, target) in enumerate(zip(inputs, targets), 1):
        start = time.perf_counter()
        prefix = f"raysplats {args.command} [{number}/{len(inputs)}] {source} -> {target}"
        try:
            detail = action(source, target, args)
            print(f"{prefix}: ok ({detail}; {time.perf_counter() - start:.1f} s)", flush=True)
        except Exception as error:  # one bad file must not stop the batch
            failures += 1
            print(f"{prefix}: FAILED: {error}", flush=True)
            if os.environ.get("RAYSPLATS_CLI_TRACEBACK"):
                traceback.print_exc()
    print(f"raysplats {args.command}: {len(inputs) - failures} of {len(inputs)} done"
          + (f", {failures} FAILED" if failures else ""), flush=True)
    return 1 if failures else 0


def main(argv=None):
    """Entry point; exits Blender with 0 (all done), 1 (some input failed) or 2 (bad command line)."""
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    try:
        ensure_addon()
        status = run(argv)
    except UsageError as error:
        print(f"raysplats: error: {error}", file=sys.stderr, flush=True)
        status = 2
    except SystemExit as exit_request:  # argparse: --help (0) or a usage error (2)
        status = exit_request.code if isinstance(exit_request.code, int) else 2
    finally:
        # Blender as a Python module (PyPI bpy) crashes at exit while add-on classes are registered; Blender
        # itself would unregister them on quit. Undo what this script registered.
        if _registered_here is not None and hasattr(bpy.types.Object, "raysplats"):
            _registered_here.unregister()
    sys.exit(status)


if __name__ == "__main__":
    main()
