# Final render (F12, `blender -b … -f/-a`): depsgraph -> native scene -> a render on a native thread, polled
# here for progress and Esc, then one bulk write per pass into the render result.
import time

import numpy as np

from .. import native
from . import sync

POLL_SECONDS = 0.05


def _border(scene, width, height):
    """Pixel rectangle (x, y, w, h) of the render border, y from the bottom as Blender counts it."""
    render = scene.render
    if not render.use_border:
        return 0, 0, width, height
    x0, x1 = int(render.border_min_x * width), int(render.border_max_x * width)
    y0, y1 = int(render.border_min_y * height), int(render.border_max_y * height)
    return x0, y0, max(1, x1 - x0), max(1, y1 - y0)


def _set_pass(render_pass, pixels):
    """One bulk write of a pass: rows bottom to top, (pixels, channels) as RenderPass.rect takes them."""
    channels = render_pass.channels
    render_pass.rect = np.ascontiguousarray(pixels, dtype=np.float32).reshape(-1, channels)


def render_final(engine, depsgraph):
    scene = depsgraph.scene
    if scene.camera is None:
        raise ValueError("The scene has no camera: set one in Scene Properties to render")
    core = native.core()
    width, height = sync.resolution(scene)
    settings = scene.raysplats

    engine.update_stats("", "Syncing scene")
    t0 = time.perf_counter()
    render_scene, stats = sync.build_render_scene(depsgraph, warn=lambda m: engine.report({"WARNING"}, m))
    t_sync = time.perf_counter() - t0
    engine.update_stats("", f"Splats {stats.splats:,} | Triangles {stats.triangles:,} | Building BVH")
    render_scene.build(settings.gaussian_mode)
    camera = sync.camera_settings(scene, scene.camera.evaluated_get(depsgraph), width, height)
    job = core.RenderJob(render_scene, camera, sync.render_settings(scene, width, height, settings.samples))
    while not job.wait(POLL_SECONDS):
        if engine.test_break():
            job.cancel()
        engine.update_progress(job.progress)
        engine.update_stats("", f"Splats {stats.splats:,} | Triangles {stats.triangles:,} | "
                                f"Rendering {int(100 * job.progress)}% of {settings.samples} samples")
    film = job.result()
    if film["cancelled"]:
        return
    print(f"RaySplats render: sync {t_sync:.2f} s, render {film['render_seconds']:.2f} s, "
          f"{stats.splats:,} splats, {stats.triangles:,} triangles")

    # Film rows run top to bottom; Blender's from the bottom up.
    x, y, w, h = _border(scene, width, height)
    rows = slice(height - y - h, height - y)
    cols = slice(x, x + w)
    if scene.render.use_border and not scene.render.use_crop_to_border:
        result = engine.begin_result(x, y, w, h)
    else:
        result = engine.begin_result(0, 0, w, h)
    layer = result.layers[0]
    _set_pass(layer.passes["Combined"], film["rgba"][rows, cols][::-1])
    depth_pass = layer.passes.get("Depth")
    if depth_pass is not None:
        depth = film["depth"][rows, cols][::-1]
        _set_pass(depth_pass, np.where(np.isfinite(depth), depth, 1e10))
    normal_pass = layer.passes.get("Normal")
    if normal_pass is not None:
        _set_pass(normal_pass, film["normal"][rows, cols][::-1])
    engine.end_result(result)
    engine.update_progress(1.0)
