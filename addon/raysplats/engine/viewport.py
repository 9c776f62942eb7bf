# Viewport (Rendered shading): the native scene is kept between redraws and rebuilt only when the depsgraph
# reports changed geometry; each redraw adds one low-cost sample (stochastic compositing, reduced resolution
# first) and the accumulated image is drawn with the gpu module, so the first image comes quickly and
# refines while nothing changes.
import numpy as np

from .. import native
from . import sync


# Diagnostics: the last viewport image drawn (samples accumulated, splats), for status displays and tests.
last_draw = {"samples": 0, "splats": 0, "draws": 0}


class ViewportState:
    def __init__(self):
        self.render_scene = None
        self.stats = None
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
    if state.render_scene is None or any(update.is_updated_geometry or update.is_updated_transform
                                         for update in depsgraph.updates):
        state.dirty = True


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
        state.render_scene, state.stats = sync.build_render_scene(depsgraph)
        state.render_scene.build(scene.raysplats.gaussian_mode)
        state.dirty = False
        state.samples = 0
    camera = view_camera(context, width, height)
    key = (width, height, tuple(np.round(camera["matrix"].ravel(), 6)), camera.get("lens"),
           camera.get("ortho_scale"))
    if key != state.key:
        state.key, state.samples, state.accumulated = key, 0, None

    target = scene.raysplats.viewport_samples
    if state.samples < target:
        settings = sync.render_settings(scene, width, height, 1, seed_offset=state.samples)
        settings["compositing"] = "STOCHASTIC"
        film = native.core().RenderJob(state.render_scene, camera, settings).result()
        rgba = film["rgba"][::-1]
        if state.accumulated is None or state.accumulated.shape != rgba.shape:
            state.accumulated = rgba.astype(np.float32)
        else:
            state.accumulated += (rgba - state.accumulated) / (state.samples + 1)
        state.samples += 1
        h, w = state.accumulated.shape[:2]
        buffer = gpu.types.Buffer("FLOAT", w * h * 4, state.accumulated.ravel())
        state.texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=buffer)
        engine.update_stats("", f"Splats {state.stats.splats:,} | Triangles {state.stats.triangles:,} | "
                                f"Sample {state.samples}/{target}")
        if state.samples < target:
            engine.tag_redraw()
    if state.texture is None:
        return
    last_draw.update(samples=state.samples, splats=state.stats.splats, draws=last_draw["draws"] + 1)
    gpu.state.blend_set("ALPHA_PREMULT")
    engine.bind_display_space_shader(scene)
    draw_texture_2d(state.texture, (0, 0), region.width, region.height)
    engine.unbind_display_space_shader()
    gpu.state.blend_set("NONE")
