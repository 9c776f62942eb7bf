# Final render (F12, `blender -b … -f/-a`): depsgraph -> native scene -> a render on a native thread, polled
# here for progress and Esc. The core renders in sample passes: the render window shows the film of the passes done
# (engine.update_result) as they complete, and Esc ends the render keeping them, as Cycles does. Each write is one
# bulk write per pass into the render result (passes.py).
import time

import numpy as np

from .. import native, progress
from ..blender import denoiser
from . import motion_blur, passes, sync

POLL_SECONDS = 0.05
# The render window shows a new image at most this often (and at most once per sample pass): a snapshot of a
# 1920 x 1080 film is ~80 MB to copy and write.
UPDATE_SECONDS = 1.0

# Diagnostics of the last final render, for status displays and tests: the samples of each partial result shown
# (with its time from the render's start), and the samples and cancel state of the image kept, its mean samples per
# pixel and camera rays (adaptive sampling takes fewer), the rendered rectangle (x, y from the bottom, w, h), and
# whether camera-ray splatting drew the camera rays (with its pre-pass's time), and whether it was denoised; `notice`:
# the information reported in the status bar (why camera rays were traced though Camera Rays as Splats is on), else "".
# `stages`: CPU and wall seconds of each stage of the frame (read, convert, scene, bvh, prepass, samples, film,
# denoise, write); `entered`, `left`: (process CPU, wall) clocks when render() was called and when it returned; `scene`: how
# the frame got its native scene ("new", or with Persistent Data "kept" when nothing in it changed, "updated" when
# changes were applied to the last frame's).
last_render = {"partial_results": [], "samples": 0, "cancelled": False, "mean_samples": 0.0, "camera_rays": 0,
               "region": None, "render_seconds": 0.0, "camera_ray_splatting": False, "notice": "",
               "splat_prepass_seconds": 0.0,
               "stages": {}, "entered": None, "left": None, "scene": "new", "denoised": False}


def _frame_scene(engine, depsgraph, clock):
    """The frame's sync.SceneSync and how it was had ("new", "kept", "updated"). With Persistent Data
    (Render Properties > Performance, `render.use_persistent_data`) Blender keeps this engine and its depsgraph from
    frame to frame (and from one F12 to the next) and reports what changed in between (depsgraph.updates), as for
    Cycles: the last frame's scene is kept, the changes applied in place (a moved object moves its instances, an
    edited one is recovered again and only its BVH rebuilt), and a change it cannot apply in place (an object added
    or removed, a material, light or world changed) builds the scene anew. Without it nothing is kept: Blender frees
    the engine, and this scene with it, after the frame."""
    warn = lambda m: engine.report({"WARNING"}, m)  # noqa: E731
    persistent = depsgraph.scene.render.use_persistent_data
    key = (depsgraph.scene.original.as_pointer(), depsgraph.view_layer.name)
    kept, engine.persistent_scene = getattr(engine, "persistent_scene", None), None
    scene_sync, how = None, "new"
    if persistent and kept is not None and kept[0] == key:
        scene_sync = kept[1]
        scene_sync.clock = clock
        with clock.stage("read"):
            change = scene_sync.update(depsgraph)
        if change == "rebuild":
            scene_sync = None
        else:
            how = "kept" if change == "none" else "updated"
    kept = None  # (a scene built anew does not share the memory of the one it replaces)
    if scene_sync is None:
        scene_sync = sync.SceneSync(depsgraph, warn, clock=clock)
    if persistent:
        # The next frame's camera-ray splatting writes into this frame's storage instead of fresh pages.
        scene_sync.render_scene.set_keep_frame_buffers(True)
        engine.persistent_scene = (key, scene_sync)
    return scene_sync, how


def _border(scene, width, height):
    """Pixel rectangle (x, y, w, h) of the render border, y from the bottom as Blender counts it: Blender's own
    arithmetic (render_init_from_main: float32 border times the size, truncated), so that it matches the size of the
    render result Blender makes for the border (the caller checks)."""
    render = scene.render
    if not render.use_border:
        return 0, 0, width, height
    f32 = np.float32
    x0, x1 = int(f32(render.border_min_x) * f32(width)), int(f32(render.border_max_x) * f32(width))
    y0, y1 = int(f32(render.border_min_y) * f32(height)), int(f32(render.border_max_y) * f32(height))
    return x0, y0, max(1, x1 - x0), max(1, y1 - y0)


def _denoise(engine, film, rows, cols):
    """Denoises the Combined pass's colour in the rendered rectangle, in place (its alpha as rendered), guided by the
    film's denoising albedo and normal (the render asked the core for them). False, with a warning, where Blender has
    no denoiser."""
    if not denoiser.available():
        engine.report({"WARNING"}, "Denoise: " + denoiser.UNAVAILABLE)
        return False
    region = film["rgba"][rows, cols]
    region[..., :3] = denoiser.denoise(region, albedo=film["denoising_albedo"][rows, cols],
                                       normal=film["denoising_normal"][rows, cols])
    return True


def render_final(engine, depsgraph):
    entered = (time.process_time(), time.perf_counter())
    scene = depsgraph.scene
    if scene.camera is None:
        raise ValueError("The scene has no camera: set one in Scene Properties to render")
    core = native.core()
    width, height = sync.resolution(scene)
    settings = scene.raysplats

    engine.update_stats("", "Syncing scene")
    clock = progress.StageClock()
    t0 = time.perf_counter()
    # Motion blur: the scene at the shutter's steps first, so that the frame's scene is read at the frame.
    # The Vector pass (written, as by Cycles, only without motion blur): the previous and next frames' placements.
    motion = frames = None
    if scene.render.use_motion_blur:
        with clock.stage("read"):
            motion = motion_blur.shutter_motion(engine, depsgraph)
    elif passes.vector_pass_enabled(depsgraph.view_layer):
        with clock.stage("read"):
            frames = motion_blur.frame_motion(engine, depsgraph)
    scene_sync, how = _frame_scene(engine, depsgraph, clock)
    render_scene, stats = scene_sync.render_scene, scene_sync.stats
    scene_sync.apply_motion(motion)
    if frames is not None:
        scene_sync.apply_frame_motion(frames)
    t_sync = time.perf_counter() - t0
    engine.update_stats("", f"Splats {stats.splats:,} | Triangles {stats.triangles:,} | Building BVH")
    with clock.stage("bvh"):
        render_scene.build(settings.gaussian_mode)
    camera = sync.camera_settings(scene, scene.camera.evaluated_get(depsgraph), width, height)
    if motion is not None and motion.camera is not None:
        camera["motion"] = motion.camera
    if motion is not None and motion.curve is not None:
        camera["shutter_curve"] = motion.curve
    if frames is not None and frames.camera is not None:
        camera["frame_motion"] = frames.camera
    # The denoiser's guides are computed when the render denoises or writes them.
    render_settings = sync.render_settings(
        scene, width, height, settings.samples, adaptive=True,
        denoising_data=settings.use_denoising or passes.denoising_passes_enabled(depsgraph.view_layer))
    render_settings.update(passes.core_settings(depsgraph.view_layer))

    # With a render border (cropped or not) Blender's render result is the border's size; Blender places it in the
    # frame itself (uncropped: the rest transparent). The core renders only the border's pixels, at their place in
    # the whole image (the same samples as a whole render there). begin_result's rectangle is clipped to Blender's
    # result, so asking for the whole frame gives the border's size as Blender computed it, which wins over ours
    # should they ever differ. Film rows run top to bottom, Blender's from the bottom up.
    x, y, w, h = _border(scene, width, height)
    result = engine.begin_result(0, 0, width, height)
    w, h = result.resolution_x, result.resolution_y
    x, y = min(x, width - w), min(y, height - h)
    rows = slice(height - y - h, height - y)
    cols = slice(x, x + w)
    if (w, h) != (width, height):
        render_settings.update(region_x=x, region_y=height - y - h, region_width=w, region_height=h)
    last_render.update(partial_results=[], samples=0, cancelled=False)
    started = time.perf_counter()
    job = None
    try:
        # Blender's thread count (Output > Performance > Threads, or `blender -t N`, which render farms set per worker
        # slot): RenderSettings.threads is the effective count, the system's when set to Auto. The image does not
        # depend on it (each pixel sample's random numbers follow from the seed, the pixel and the sample).
        job = core.RenderJob(render_scene, camera, render_settings, max_threads=scene.render.threads)
        shown_samples, shown_at = 0, started
        while not job.wait(POLL_SECONDS):
            if engine.test_break():
                job.cancel()
            engine.update_progress(job.progress)
            done = job.snapshot_samples
            engine.update_stats("", f"Splats {stats.splats:,} | Triangles {stats.triangles:,} | "
                                    f"Sample {done}/{settings.samples} ({int(100 * job.progress)}%)")
            if done > shown_samples and time.perf_counter() - shown_at >= UPDATE_SECONDS:
                film = job.snapshot(passes.written_keys(result.layers[0]))
                passes.write_passes(result.layers[0], film, rows, cols)
                engine.update_result(result)
                shown_samples, shown_at = film["samples"], time.perf_counter()
                last_render["partial_results"].append((shown_at - started, shown_samples))
        film = job.result()
        # Cancelled (Esc), the film holds the sample passes done: kept, as Cycles keeps them.
        # Adaptive sampling: pixels took fewer samples than the maximum; the mean says how many.
        mean_samples = film["camera_rays"] / (w * h)
        print(f"RaySplats render: sync {t_sync:.2f} s, render {film['render_seconds']:.2f} s, "
              f"{film['samples']} of {settings.samples} samples{' (cancelled)' if film['cancelled'] else ''} "
              f"(mean {mean_samples:.1f} per pixel), {w} x {h} pixels, {stats.splats:,} splats, "
              f"{stats.triangles:,} triangles")
        notice = ""
        if film["camera_rays_traced_reason"]:
            # Information, not a warning: with the setting on by default, every Lit render would otherwise warn.
            # The core says why it stepped aside ("needs a camera without depth of field", ...).
            notice = (f"Camera Rays as Splats {film['camera_rays_traced_reason']}: this render's camera rays were "
                      f"ray traced")
            engine.report({"INFO"}, notice)
        denoised = False
        if scene.raysplats.use_denoising and film["samples"] > 0:
            with clock.stage("denoise"):
                denoised = _denoise(engine, film, rows, cols)
        with clock.stage("write"):
            passes.write_passes(result.layers[0], film, rows, cols)
    except BaseException:
        # Any failure (the job refused, a pass Blender refuses, an error in the loop): the render thread stops now
        # rather than when the traceback lets the job go, and no half-written result is left open in Blender.
        if job is not None:
            job.cancel()
        engine.end_result(result, cancel=True)
        raise
    with clock.stage("write"):
        engine.end_result(result)
        # The Cryptomatte passes' metadata, on the render's own result as Cycles puts it there (get_result), so that the
        # compositor's Cryptomatte node and saved EXR files name what the ids are.
        metadata = passes.cryptomatte_metadata(depsgraph.view_layer, scene_sync.cryptomatte_names)
        if metadata:
            render_result = engine.get_result()
            for field, value in metadata.items():
                render_result.stamp_data_add_field(field, value)
    for stage, prefix in (("prepass", "splat_prepass"), ("samples", "sample"), ("film", "film")):
        clock.add(stage, film[prefix + "_cpu_seconds"], film[prefix + "_seconds"])
    last_render.update(stages={name: tuple(values) for name, values in clock.stages.items()}, scene=how,
                       entered=entered, left=(time.process_time(), time.perf_counter()))
    last_render.update(samples=film["samples"], cancelled=film["cancelled"], mean_samples=mean_samples, denoised=denoised,
                       camera_rays=film["camera_rays"], region=(x, y, w, h), render_seconds=film["render_seconds"],
                       camera_ray_splatting=film["camera_ray_splatting"], notice=notice,
                       splat_prepass_seconds=film["splat_prepass_seconds"])
    engine.update_progress(1.0)
