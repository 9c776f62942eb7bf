# Viewport (Rendered shading): the native scene is kept between redraws; the depsgraph's changes to Gaussian and
# mesh objects are applied in place (sync.SceneSync.update: the renderer rebuilds only the Gaussian chunks or mesh
# that changed, or only moves instances), anything else builds it again; each redraw adds one low-cost sample
# (stochastic compositing, reduced resolution first) and the accumulated image is drawn with the gpu module, so
# the first image comes quickly and refines while nothing changes.
import time

import numpy as np

from .. import native
from . import sync


# Diagnostics: the last viewport image drawn (samples accumulated, splats), for status displays and tests.
last_draw = {"samples": 0, "splats": 0, "draws": 0}


class ViewportState:
    def __init__(self):
        self.sync = None
        self.dirty = True
        self.key = None
        self.accumulated = None
        self.samples = 0
        self.texture = None


def view_camera(context, width, height):
    """A native camera matching the 3D view (perspective or orthographic), from its matrices."""
    region_3d = context.region_data
    view_to_world = np.array(region_3d.view_matrix.inverted(), dtype=np.float32)
    projection = np.array(region_3d.window_matrix, dtype=np.float64)
    # OpenGL frustum: (r + l) / (r - l) = 2 shift_x and (t + b) / (t - b) = 2 shift_y · width / height, with
    # shifts in units of the (horizontally fitted) image width. A perspective matrix has them in column 2,
    # an orthographic one negated in column 3.
    if region_3d.is_perspective:
        off_x, off_y = projection[0, 2], projection[1, 2]
    else:
        off_x, off_y = -projection[0, 3], -projection[1, 3]
    camera = {"matrix": view_to_world, "sensor_fit": "HORIZONTAL", "sensor_width": 36.0,
              "clip_start": float(context.space_data.clip_start), "clip_end": float(context.space_data.clip_end),
              "shift_x": off_x / 2.0, "shift_y": off_y / 2.0 * height / width}
    if region_3d.is_perspective:
        # projection[0, 0] = 2 lens / sensor_width for a horizontally fitted sensor.
        camera.update(type="PERSP", lens=float(projection[0, 0] * 36.0 / 2.0))
    else:
        camera.update(type="ORTHO", ortho_scale=float(2.0 / projection[0, 0]))
    return camera


def view_update(engine, context, depsgraph):
    state = engine.viewport_state
    if state.sync is None or state.dirty:
        state.dirty = True
        return
    try:
        change = state.sync.update(depsgraph)
    except Exception as error:  # a bad edit (NaN vertices, ...): build again, which reports it
        print(f"RaySplats viewport: {error}")
        change = "rebuild"
    if change == "rebuild":
        state.dirty = True
    elif change == "updated":
        state.samples, state.accumulated = 0, None
        last_draw["updates"] = last_draw.get("updates", 0) + 1


def view_draw(engine, context, depsgraph):
    import gpu
    from gpu_extras.presets import draw_texture_2d

    state = engine.viewport_state
    scene = depsgraph.scene
    region = context.region
    # Start at a quarter of the resolution, full resolution once the view holds still.
    divisor = 4 if state.samples == 0 else 1
    width, height = max(1, region.width // divisor), max(1, region.height // divisor)
    if state.dirty:
        state.sync = sync.SceneSync(depsgraph, interactive=True)
        state.sync.render_scene.build(scene.raysplats.gaussian_mode)
        state.dirty = False
        state.samples, state.accumulated = 0, None
        last_draw["rebuilds"] = last_draw.get("rebuilds", 0) + 1
    camera = view_camera(context, width, height)
    key = (width, height, tuple(np.round(camera["matrix"].ravel(), 6)), camera.get("lens"),
           camera.get("ortho_scale"))
    if key != state.key:
        state.key, state.samples, state.accumulated = key, 0, None

    target = scene.raysplats.viewport_samples
    if state.samples < target:
        settings = sync.render_settings(scene, width, height, 1, seed_offset=state.samples)
        settings["compositing"] = "STOCHASTIC"
        film = native.core().RenderJob(state.sync.render_scene, camera, settings).result()
        rgba = film["rgba"][::-1]
        if state.accumulated is None or state.accumulated.shape != rgba.shape:
            state.accumulated = rgba.astype(np.float32)
        else:
            state.accumulated += (rgba - state.accumulated) / (state.samples + 1)
        state.samples += 1
        h, w = state.accumulated.shape[:2]
        buffer = gpu.types.Buffer("FLOAT", w * h * 4, state.accumulated.ravel())
        state.texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=buffer)
        stats = state.sync.stats
        engine.update_stats("", f"Splats {stats.splats:,} | Triangles {stats.triangles:,} | "
                                f"Sample {state.samples}/{target}")
        if state.samples < target:
            engine.tag_redraw()
    if state.texture is None:
        return
    last_draw.update(samples=state.samples, splats=state.sync.stats.splats, draws=last_draw["draws"] + 1,
                     time=time.perf_counter())
    gpu.state.blend_set("ALPHA_PREMULT")
    engine.bind_display_space_shader(scene)
    draw_texture_2d(state.texture, (0, 0), region.width, region.height)
    engine.unbind_display_space_shader()
    gpu.state.blend_set("NONE")
