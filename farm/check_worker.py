# Checks that a render-farm worker's Blender can render with RaySplats as it starts for a job: the add-on enabled in
# its preferences, the RAYSPLATS engine registered, the native module for this Blender's Python loaded, and a tiny
# render through the engine. Prints one line starting "check_worker:" and exits 0 when all hold, else 1 with the
# reason. farm/install_worker.py runs it after installing; run it on any worker to see why frames fail there:
#   blender -b -noaudio --python farm/check_worker.py            (a Blender binary: its own preferences)
#   PYTHON farm/check_worker.py                                   (Blender as a Python module, PyPI bpy)
# BLENDER_USER_RESOURCES picks another user folder, as for Blender itself.
import importlib
import os
import sys
import tempfile

# Blender runs --python scripts with bpy already imported; a plain Python interpreter imports it here.
AS_MODULE = "bpy" not in sys.modules

import bpy  # noqa: E402

ENGINE = "RAYSPLATS"
WORLD_COLOR = (0.2, 0.4, 0.6)  # linear; the check render must show it (an engine that drew nothing leaves black)


def _blender():
    return (f"Blender {bpy.app.version_string} (Python {sys.version_info.major}.{sys.version_info.minor}"
            f"{', as a Python module' if AS_MODULE else ''})")


def _registered_engines():
    # getattr: Blender 4.x lists base classes without bl_idname (HydraRenderEngine) among the subclasses.
    return {getattr(engine, "bl_idname", None) for engine in bpy.types.RenderEngine.__subclasses__()}


def _enabled_addon():
    """The module name of the enabled RaySplats add-on: "raysplats" (Blender 3.x add-on folder, or the source tree
    linked by scripts/install_addon.sh) or "bl_ext.<repository>.raysplats" (an extension, Blender 4.2+)."""
    names = [name for name in bpy.context.preferences.addons.keys() if name.rsplit(".", 1)[-1] == "raysplats"]
    return names[0] if names else None


def _enable_installed_extension():
    """Enables RaySplats from the extension repository it is installed in (Blender 4.2+), as a job script that uses
    Blender as a Python module does: bpy.ops.preferences.addon_enable(module="bl_ext.user_default.raysplats")."""
    for repo in bpy.context.preferences.extensions.repos:
        folder = repo.custom_directory if repo.use_custom_directory else repo.directory
        if repo.enabled and os.path.isdir(os.path.join(folder, "raysplats")):
            bpy.ops.preferences.addon_enable(module=f"bl_ext.{repo.module}.raysplats")
            return


def _render_check(package):
    """Renders an empty 8 x 8 scene (camera, world colour) with the engine and returns the mean error of its pixels
    against the world colour (written as a Standard-view PNG, read back)."""
    scene = bpy.data.scenes.new("raysplats_worker_check")
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.world = bpy.data.worlds.new("raysplats_worker_check")
    scene.world.color = WORLD_COLOR
    # A world made in Blender 5.0+ has a node tree, whose Background colour is what renders.
    for node in scene.world.node_tree.nodes if scene.world.node_tree else ():
        if node.type == "BACKGROUND":
            node.inputs["Color"].default_value = (*WORLD_COLOR, 1.0)
            node.inputs["Strength"].default_value = 1.0
    scene.render.engine = ENGINE
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.render.resolution_percentage = 100
    scene.raysplats.samples = 1
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    scene.render.use_file_extension = False
    with tempfile.TemporaryDirectory(prefix="raysplats_check_") as folder:
        scene.render.filepath = os.path.join(folder, "check.png")
        bpy.ops.render.render(write_still=True, scene=scene.name)
        if not os.path.exists(scene.render.filepath):
            raise RuntimeError("the check render wrote no image (see Blender's messages above)")
        image = bpy.data.images.load(scene.render.filepath)
        pixels = list(image.pixels)
        bpy.data.images.remove(image)

    def srgb(value):  # the Standard view transform's encoding (IEC 61966-2-1)
        return 12.92 * value if value <= 0.0031308 else 1.055 * value ** (1 / 2.4) - 0.055

    expected = [srgb(channel) for channel in WORLD_COLOR]
    count = len(pixels) // 4
    return sum(abs(pixels[4 * i + c] - expected[c]) for i in range(count) for c in range(3)) / (3 * count)


def check():
    """Returns (ok, message)."""
    if AS_MODULE:
        # Blender as a Python module starts from factory preferences, with no extension enabled (reading the user's,
        # bpy.ops.wm.read_userpref, crashes the 4.2 module): a job script enables the installed extension itself.
        _enable_installed_extension()
    name = _enabled_addon()
    if name is None:
        return False, (f"the RaySplats add-on is not enabled in {_blender()} (user folder "
                       f"{bpy.utils.resource_path('USER')}): install it with farm/install_worker.py")
    package = sys.modules.get(name) or importlib.import_module(name)
    if ENGINE not in _registered_engines():
        return False, f"the add-on {name} is enabled but the {ENGINE} engine is not registered in {_blender()}"
    native = importlib.import_module(name + ".native")
    try:
        core = native.core()
    except native.NativeModuleMissing as error:
        return False, f"{_blender()}: {error}"
    error = _render_check(package)
    if error > 2.0 / 255:
        return False, (f"{_blender()}: the {ENGINE} check render differs from its world colour by {error:.3f} on "
                       "average (a working engine: under 2/255)")
    return True, (f"{ENGINE} works in {_blender()}: add-on {name} at {os.path.dirname(package.__file__)}, "
                  f"native module {os.path.basename(core.__file__)}")


def main():
    try:
        ok, message = check()
    except Exception as error:  # anything else that stops a worker: said, not a traceback
        ok, message = False, f"{_blender()}: {type(error).__name__}: {error}"
    print(f"check_worker: {message}", file=sys.stdout if ok else sys.stderr, flush=True)
    sys.stderr.flush()
    if AS_MODULE:
        # Blender as a module crashes at interpreter exit while add-on classes are registered (the enabled add-on's
        # are); Blender itself would unregister them on quit. Nothing is left to write, so leave at once.
        os._exit(0 if ok else 1)
    sys.exit(0 if ok else 1)


main()
