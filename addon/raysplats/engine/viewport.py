# Viewport (Rendered shading). The UI thread never waits on a sample: view_draw starts a native RenderJob (its own
# thread) and returns; each redraw draws the newest image the job has (a snapshot after each sample pass, then its
# result), and a timer tags a redraw when a newer one is ready. A view change (camera, size, settings) cancels the job
# and starts another: first one sample at a quarter of the resolution (the first image comes quickly), then the
# full resolution in sample passes. Edits to Gaussian and mesh objects are applied in place (sync.SceneSync.update:
# the renderer rebuilds only the Gaussian chunks or mesh that changed, or only moves instances) once the running job
# has stopped, since the core refuses scene changes during a render; anything else builds the scene again.
import os
import time

import bpy
import numpy as np

from .. import native
from ..blender import denoiser
from . import sync

POLL_SECONDS = 0.05  # how often the timer looks for a newer image (a flag and a counter read; no copies)
PREVIEW_DIVISOR = 4  # the first image of a view: one sample at a quarter of the resolution
# The viewport render leaves one core to Blender's UI thread (and its drawing, in software GL on machines without a
# GPU), which would otherwise compete with every render thread, and its own thread runs below normal priority.
# Under blender_gui.viewport_rendered on 2 shared cores, all threads at normal priority let the UI timer tick several
# times less often than one thread fewer below normal priority (docs/benchmarks.md, Viewport threads).
RENDER_THREADS = max(1, (os.cpu_count() or 2) - 1)

# Diagnostics: the newest viewport image (its samples, splats; draws: images drawn so far, time: when the last came)
# and the longest time view_draw or view_update kept the UI thread (longest_ui_call, seconds; tests reset it), for
# status displays and tests.
last_draw = {"samples": 0, "splats": 0, "draws": 0, "longest_ui_call": 0.0}


def _timed(entry_point):
    """Records the UI-thread time of an entry point in last_draw["longest_ui_call"]."""
    def timed(engine, context, depsgraph):
        start = time.perf_counter()
        try:
            entry_point(engine, context, depsgraph)
        finally:
            last_draw["longest_ui_call"] = max(last_draw["longest_ui_call"], time.perf_counter() - start)
    timed.__doc__ = entry_point.__doc__
    return timed


class ViewportState:
    def __init__(self):
        self.sync = None
        self.dirty = True
        self.key = None           # what `job` renders: image size, view and settings; None: start again
        self.view = None          # the view drawn last: (key, preview camera, preview width, height)
        self.job = None           # the newest render; older ones are cancelled and end in `retiring`
        self.job_is_preview = False
        self.retiring = []
        self.shown_samples = 0    # samples of the image drawn from `job` (0: none yet)
        self.samples = 0          # samples of the image on screen
        self.texture = None
        self.polling = False


def _jobs(state):
    return ([state.job] if state.job is not None else []) + state.retiring


def _stop_jobs(state):
    """Cancels every job and waits for them (each ends within one tile's sample pass): the scene can be changed."""
    for job in _jobs(state):
        job.cancel()
    for job in _jobs(state):
        job.wait(1e9)
    state.job, state.retiring, state.key = None, [], None


def _retire(state):
    if state.job is not None:
        state.job.cancel()
        state.retiring.append(state.job)
        state.job = None
    # Dropped once ended: dropping a running job would join its thread here, on the UI thread.
    state.retiring = [job for job in state.retiring if not job.wait(0.0)]


def _has_newer_image(state):
    job = state.job
    return job is not None and (job.snapshot_samples > state.shown_samples or job.wait(0.0))


def _engine_exists(engine):
    """False once Blender has freed the engine (the view left Rendered shading): its Python object then raises
    ReferenceError on any attribute."""
    try:
        engine.as_pointer()
        return True
    except ReferenceError:
        return False


def _poll(engine, state):
    """Timer: tags the rendered 3D views for a redraw when the job has a newer image; stops with the job, and
    cancels it when the engine has been freed."""
    if not _engine_exists(engine):
        for job in _jobs(state):
            job.cancel()
        state.polling = False
        return None
    if state.job is None:
        state.polling = False
        return None
    if _has_newer_image(state):
        for window in bpy.context.window_manager.windows:
            for area in window.screen.areas:
                if area.type == "VIEW_3D" and area.spaces.active.shading.type == "RENDERED":
                    area.tag_redraw()
    return POLL_SECONDS


def _start_polling(engine, state):
    if not state.polling:
        state.polling = True
        bpy.app.timers.register(lambda: _poll(engine, state), first_interval=POLL_SECONDS)


def view_camera(context, width, height, depsgraph=None):
    """A native camera matching the 3D view (perspective or orthographic), from its matrices. Looking through the
    scene's camera (the view's own with Local Camera), it has that camera's depth of field (Cycles' viewport does the
    same); any other view is a pinhole."""
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
    if region_3d.view_perspective == "CAMERA":
        space = context.space_data
        camera_object = space.camera if space.use_local_camera else context.scene.camera
        if camera_object is not None:
            if depsgraph is not None:
                camera_object = camera_object.evaluated_get(depsgraph)
            camera.update(sync.depth_of_field(camera_object, lens=camera.get("lens")))
    return camera


@_timed
def view_update(engine, context, depsgraph):
    state = engine.viewport_state
    if state.sync is None or state.dirty:
        state.dirty = True
        return
    if not any(state.sync.changes_scene(update) for update in depsgraph.updates):
        return  # selection and the like: the render goes on
    _stop_jobs(state)  # the core refuses scene changes while a job renders the scene
    try:
        change = state.sync.update(depsgraph)
    except Exception as error:  # a bad edit (NaN vertices, ...): build again, which reports it
        print(f"RaySplats viewport: {error}")
        change = "rebuild"
    if change == "rebuild":
        state.dirty = True
    elif change == "updated":
        last_draw["updates"] = last_draw.get("updates", 0) + 1
        if state.view is not None:
            # The edited scene's first image is rendered now, on the job's thread, while Blender finishes the edit on
            # the UI thread (an Edit Mode move of a few splats of showroom_1.5M: its undo step alone, a copy of the
            # whole mesh, takes longer than the preview); the next redraw finds it ready, the view being unchanged.
            _start_preview(engine, state, depsgraph.scene, *state.view)


def _start_preview(engine, state, scene, key, preview_camera, preview_width, preview_height):
    """The first image of a view: one sample at a quarter of the resolution (PREVIEW_DIVISOR), always traced: camera
    ray splatting's pre-pass projects every Gaussian whatever the resolution (0.25 s of a 0.49 s preview of the whole
    showroom_1.5M.ply at 480 x 270, twice the traced preview), and the preview is there to come quickly after a view
    change or an edit; the passes that replace it are splatted when the setting is on."""
    state.key, state.job_is_preview, state.samples = key, True, 0
    _start_job(engine, state, scene, preview_camera, preview_width, preview_height, 1, splatting=False)


def _start_job(engine, state, scene, camera, width, height, samples, seed_offset=0, splatting=None):
    # The denoiser's guides only when the finished image is denoised.
    settings = sync.render_settings(scene, width, height, samples, seed_offset=seed_offset,
                                    denoising_data=scene.raysplats.use_preview_denoising)
    settings["compositing"] = "STOCHASTIC"  # no sorting: the cheapest sample, refined by the passes
    if splatting is not None:
        settings["camera_ray_splatting"] = splatting
    state.job = native.core().RenderJob(state.sync.render_scene, camera, settings,
                                        max_threads=RENDER_THREADS, below_normal_priority=True)
    state.shown_samples = 0
    _start_polling(engine, state)


def _take_image(state, denoise=False):
    """The job's newest Combined film (its result once it has ended, else the newest pass's snapshot, rows top to
    bottom) and its samples; None when there is nothing newer than what is drawn. With `denoise`, a job's result
    (all its samples) is denoised where Blender has a denoiser, guided by its denoising albedo and normal (the job was
    started with denoising_data when preview denoising is on)."""
    job = state.job
    if job.wait(0.0):
        state.job = None  # (before result(), which raises the render's error: reported once, not every redraw)
        film = job.result()
        # (A job started before preview denoising was turned on has no guides: its image is drawn as rendered.)
        if denoise and film["samples"] > 0 and denoiser.available() and "denoising_albedo" in film:
            film["rgba"][..., :3] = denoiser.denoise(film["rgba"], albedo=film["denoising_albedo"],
                                                     normal=film["denoising_normal"])
    elif job.snapshot_samples > state.shown_samples:
        film = job.snapshot(["rgba"])  # the one channel drawn, not the whole film
    else:
        return None
    state.shown_samples = film["samples"]
    if film["samples"] == 0:
        return None  # cancelled before its first pass
    return film["rgba"], film["samples"]


@_timed
def view_draw(engine, context, depsgraph):
    import gpu

    state = engine.viewport_state
    scene = depsgraph.scene
    region = context.region
    if state.dirty:
        _stop_jobs(state)
        # A scene that cannot be built (reported once by the engine's entry point) is not built again at every
        # redraw: the next change of the scene (view_update) marks it dirty and tries again.
        state.sync, state.dirty = None, False
        state.sync = sync.SceneSync(depsgraph, interactive=True)  # the job builds its BVH on its own thread
        last_draw["rebuilds"] = last_draw.get("rebuilds", 0) + 1
    if state.sync is None:
        return  # the last build failed; nothing to draw until the scene changes
    width, height = region.width, region.height
    camera = view_camera(context, width, height, depsgraph)
    settings = sync.render_settings(scene, width, height, scene.raysplats.viewport_samples)
    key = (width, height, tuple(np.round(camera["matrix"].ravel(), 6)),
           tuple(sorted((name, value) for name, value in camera.items() if name != "matrix")),
           tuple(sorted(settings.items())), scene.raysplats.use_preview_denoising)
    if key != state.key:
        _retire(state)
        # The old image stays on screen until the new one comes, counted as no samples of the new view.
        preview_width, preview_height = max(1, width // PREVIEW_DIVISOR), max(1, height // PREVIEW_DIVISOR)
        state.view = (key, view_camera(context, preview_width, preview_height, depsgraph), preview_width,
                      preview_height)
        _start_preview(engine, state, scene, *state.view)
    elif state.retiring:
        _retire(state)

    image = _take_image(state, scene.raysplats.use_preview_denoising) if state.job is not None else None
    if image is not None:
        rgba, samples = image
        h, w = rgba.shape[:2]
        buffer = gpu.types.Buffer("FLOAT", w * h * 4, rgba.ravel())
        # 32-bit floats as the film has them (RGBA16F made Blender convert every value on the UI thread).
        state.texture = gpu.types.GPUTexture((w, h), format="RGBA32F", data=buffer)
        state.samples = samples
        stats = state.sync.stats
        engine.update_stats("", f"Splats {stats.splats:,} | Triangles {stats.triangles:,} | "
                                f"Sample {state.samples}/{scene.raysplats.viewport_samples}")
        last_draw.update(samples=samples, splats=stats.splats, draws=last_draw["draws"] + 1, time=time.perf_counter())
    if state.job is None and state.job_is_preview:
        # The preview has ended: the full image, in sample passes (seeds after the preview's).
        state.job_is_preview = False
        _start_job(engine, state, scene, camera, width, height, scene.raysplats.viewport_samples, seed_offset=1)
    if state.texture is not None:
        draw_image(engine, scene, state.texture, region)


def draw_image(engine, scene, texture, region):
    """Draws the film texture over the region through Blender's display transform. Blender's GPU state (blending,
    the display-space shader) is restored even when drawing fails: left set, it would spoil every later drawing of
    the window."""
    import gpu
    from gpu_extras.presets import draw_texture_2d

    gpu.state.blend_set("ALPHA_PREMULT")
    try:
        engine.bind_display_space_shader(scene)
        try:
            # Film rows run top to bottom, texture rows bottom to top: drawn with a negative height, flipped for free.
            draw_texture_2d(texture, (0, region.height), region.width, -region.height)
        finally:
            engine.unbind_display_space_shader()
    finally:
        gpu.state.blend_set("NONE")
