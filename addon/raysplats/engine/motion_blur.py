# Motion blur in final renders: where each object and the camera are across the shutter; and for the Vector pass
# (motion blur off, as Cycles writes it), where they are at the previous and the next frame. Blender's own settings, as
# Cycles reads them (intern/cycles/blender/sync.cpp, object.cpp, util.h): Render Properties > Motion Blur
# (`render.use_motion_blur`, `motion_blur_shutter` in frames, `motion_blur_position`, Scene.cycles' before 4.2,
# the shutter curve) and each object's `Object.cycles.use_motion_blur` and `motion_steps` (Object Properties > Motion
# Blur; the Cycles add-on defines them, and an object without them blurs with one step, their defaults). The scene is evaluated at each step's time
# with RenderEngine.frame_set and put back at the frame afterwards, as Cycles' sync_motion does. Deformation blur (the
# object's Object.cycles.use_deform_motion, Object Properties > Motion Blur > Deformation): a mesh or polygon splat
# object whose evaluated vertices move during the shutter (shape keys, an armature, deforming modifiers) has its
# vertex positions read at the same steps, in the same loop.
import math

import numpy as np

from ..blender import compat, mesh_read
from ..objects import splat_object

# Where the shutter's interval lies around the frame (Cycles: frame_center_delta of sync_motion): the interval's
# centre is the frame plus this many shutters.
_CENTRE_OFFSET = {"START": 0.5, "CENTER": 0.0, "END": -0.5}


class ShutterMotion:
    """What moves during the shutter: `objects` maps an instance_key to the object's matrix_world at its motion
    steps (an (n, 4, 4) float32 array, from the shutter's opening to its closing) for every object that moves;
    `camera` is the camera's normalized matrix_world at its steps, or None when it is still; `curve` the shutter
    curve (shutter_curve), or None. `deformation` maps an instance_key to its evaluated mesh's vertex positions at
    the same steps (an (n, vertices, 3) float32 array, in the object's own frame) for every mesh that deforms
    (use_deform_motion); `warnings` says which deformations were left out."""

    def __init__(self, objects, camera, curve=None, deformation=None, warnings=()):
        self.objects, self.camera, self.curve = objects, camera, curve
        self.deformation = deformation if deformation is not None else {}
        self.warnings = list(warnings)


# Values of the shutter curve handed to the core: Cycles' RAMP_TABLE_SIZE (blender/curves.cpp, curvemapping_to_array).
SHUTTER_CURVE_VALUES = 256


def shutter_curve(render):
    """Render Properties > Motion Blur > Shutter Curve (render.motion_blur_shutter_curve) at SHUTTER_CURVE_VALUES
    equally spaced times across the shutter, as Cycles samples it; None when it is flat (Blender's default: the
    shutter fully open throughout), which the core draws uniformly."""
    mapping = render.motion_blur_shutter_curve
    mapping.initialize()
    curve = mapping.curves[0]
    values = np.array([mapping.evaluate(curve, i / (SHUTTER_CURVE_VALUES - 1)) for i in range(SHUTTER_CURVE_VALUES)],
                      dtype=np.float32)
    # A curve drawn below 0 (an unclipped curve, or rounding at a closed end) is a closed shutter there.
    values = np.maximum(values, 0.0)
    return None if np.all(values == values[0]) else values


def position_settings(scene):
    """What holds motion_blur_position (Start, Center or End on Frame): the scene's render settings, or before 4.2
    Cycles' scene settings."""
    return scene.render if compat.MOTION_BLUR_POSITION_IN_RENDER_SETTINGS else scene.cycles


def instance_key(instance):
    """The identity of a depsgraph object instance that stays the same across frame_set calls: the original
    object, and for an instance its instancer and persistent id."""
    obj = instance.object
    if instance.is_instance:
        return obj.original.as_pointer(), instance.parent.original.as_pointer(), tuple(instance.persistent_id)
    return (obj.original.as_pointer(),)


def _object_settings(obj):
    """(use_motion_blur, motion_steps, use_deform_motion) of an object: Object.cycles' (Object Properties > Motion
    Blur), or the defaults (on, 1, on) where the Cycles add-on is not there to define them."""
    settings = getattr(obj, "cycles", None)
    if settings is None or not hasattr(settings, "use_motion_blur"):
        return True, 1, True
    return (bool(settings.use_motion_blur), max(1, int(settings.motion_steps)),
            bool(getattr(settings, "use_deform_motion", True)))


def uses_deform_motion(obj, parent=None):
    """Whether an object's deformation is blurred, Cycles' object_use_deform_motion (blender/object.cpp): its own
    Deformation switch, and an instance's instancer's too."""
    use = _object_settings(obj)[2]
    if parent is not None and parent != obj:
        use = use and _object_settings(parent)[2]
    return use


def may_deform(obj, scene):
    """Whether the evaluated mesh of a mesh or polygon splat object (original) may differ from frame to frame, so that
    its vertices are read at every step: Blender's Object.is_deform_modified (shape keys, deforming modifiers, an
    armature or a lattice parent) or any modifier at all (Geometry Nodes). A mesh without these keeps its vertices and
    costs no read. Point splat objects (compact points, Blender's splats) are not deformed (their object's motion
    only)."""
    return obj.type == "MESH" and splat_object.kind_of(obj) in (None, splat_object.POLYGONS) \
        and (len(obj.modifiers) > 0 or obj.is_deform_modified(scene, "RENDER"))


def motion_step_count(obj, parent=None):
    """How many times an object is placed across the shutter, Cycles' object_motion_steps: 0 when its motion blur
    (or its instancer's) is off, else 2^steps + 1 (an odd count, so one is the interval's centre, and a power of two
    apart, so objects of different step counts share their times)."""
    use, steps, _ = _object_settings(obj)
    if parent is not None and parent != obj:
        parent_use, parent_steps, _ = _object_settings(parent)
        use, steps = use and parent_use, max(steps, parent_steps)
    return (2 << (steps - 1)) + 1 if use else 0


def _step_times(centre, shutter, count):
    """The frame times of `count` equally spaced steps across the shutter [centre - shutter/2, centre + shutter/2]."""
    return [centre + shutter * (k / (count - 1) - 0.5) for k in range(count)]


def _moving(matrices):
    return matrices is not None and any(not np.array_equal(m, matrices[0]) for m in matrices[1:])


def _vertex_positions(mesh):
    """The vertex positions of an evaluated mesh, (vertices, 3) float32."""
    positions = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh_read.read_vertex_positions(mesh, positions)
    return positions.reshape(-1, 3)


def _placements(engine, depsgraph, times, keys, camera, deforming=frozenset()):
    """{(instance key, time): matrix_world} of the instances whose keys are in `keys`, {("camera", time): the
    camera's normalized matrix_world} when `camera`, and {("vertices", instance key, time): its evaluated mesh's
    vertex positions} of the instances whose keys are in `deforming`, at each frame time of `times`
    (engine.frame_set); the frame is set back (its subframe too) before returning."""
    scene = depsgraph.scene
    frame, subframe = scene.frame_current, float(scene.frame_subframe)
    placed = {}
    try:
        for time in times:
            whole = math.floor(time)
            engine.frame_set(whole, time - whole)
            for instance in depsgraph.object_instances:
                key = instance_key(instance)
                if key in keys:
                    placed[key, time] = np.array(instance.matrix_world, dtype=np.float32)
                if key in deforming:
                    placed["vertices", key, time] = _vertex_positions(instance.object.data)
            if camera:
                placed["camera", time] = np.array(scene.camera.evaluated_get(depsgraph).matrix_world.normalized(),
                                                  dtype=np.float32)
    finally:
        engine.frame_set(frame, subframe)
    return placed


def frame_motion(engine, depsgraph):
    """The Vector pass's motion: a ShutterMotion whose matrices are each object's and the camera's at the previous
    and the next frame (Cycles' motion pass, MOTION_PASS: the frame before and after, whatever the shutter), for every
    object drawn at both; the camera's even when still (the pass projects through it); and whose deformation is a
    deforming mesh's vertices at both (use_deform_motion; not polygon splat objects, whose Gaussians move by their
    object's matrices in this pass), when it has as many at both."""
    scene = depsgraph.scene
    time = scene.frame_current + float(scene.frame_subframe)
    keys, deforming = set(), set()
    for instance in depsgraph.object_instances:
        key = instance_key(instance)
        keys.add(key)
        obj, parent = instance.object.original, instance.parent.original if instance.is_instance else None
        if uses_deform_motion(obj, parent) and may_deform(obj, scene) and splat_object.kind_of(obj) is None:
            deforming.add(key)
    placed = _placements(engine, depsgraph, (time - 1.0, time + 1.0), keys, scene.camera is not None, deforming)
    objects = {}
    for key in keys:
        if (key, time - 1.0) in placed and (key, time + 1.0) in placed:
            objects[key] = np.stack((placed[key, time - 1.0], placed[key, time + 1.0]))
    deformation = {}
    for key in deforming:
        positions = [placed.get(("vertices", key, t)) for t in (time - 1.0, time + 1.0)]
        if all(p is not None for p in positions) and len(positions[0]) == len(positions[1]):
            deformation[key] = np.stack(positions)
    camera = np.stack((placed["camera", time - 1.0], placed["camera", time + 1.0])) if scene.camera else None
    return ShutterMotion(objects, camera, deformation=deformation)


def shutter_motion(engine, depsgraph):
    """The ShutterMotion of the frame (None when Motion Blur is off). Evaluates the scene at every step's time with
    engine.frame_set and sets the frame back (its subframe too) before returning, so the depsgraph is the frame's
    again."""
    scene = depsgraph.scene
    render = scene.render
    if not render.use_motion_blur:
        return None
    shutter = float(render.motion_blur_shutter)
    frame, subframe = scene.frame_current, float(scene.frame_subframe)
    centre = frame + subframe + _CENTRE_OFFSET[position_settings(scene).motion_blur_position] * shutter
    # Which times each object and the camera need (rounded, so that objects of different step counts share them),
    # and which meshes may deform (their vertices are read at their steps too).
    wanted, deforming, names = {}, set(), {}
    for instance in depsgraph.object_instances:
        obj, parent = instance.object.original, instance.parent.original if instance.is_instance else None
        count = motion_step_count(obj, parent)
        if count:
            key = instance_key(instance)
            wanted[key] = count
            if uses_deform_motion(obj, parent) and may_deform(obj, scene):
                deforming.add(key)
                names[key] = obj.name
    camera_count = motion_step_count(scene.camera.original) if scene.camera is not None else 0
    times = sorted({round(t, 9) for count in set(wanted.values()) | ({camera_count} - {0})
                    for t in _step_times(centre, shutter, count)})
    placed = _placements(engine, depsgraph, times, wanted, camera_count > 0, deforming)

    def at_steps(prefix, count):
        """What `placed` holds under `prefix` + (time,) at each of `count` steps (None where it holds nothing)."""
        return [placed.get(prefix + (round(t, 9),)) for t in _step_times(centre, shutter, count)]

    def steps(key, count):
        matrices = at_steps((key,), count)
        return None if any(m is None for m in matrices) else np.stack(matrices)

    objects = {}
    for key, count in wanted.items():
        matrices = steps(key, count)
        if _moving(matrices):
            objects[key] = matrices
    deformation, warnings = {}, []
    for key in deforming:
        positions = at_steps(("vertices", key), wanted[key])
        if any(p is None for p in positions):
            continue
        if any(len(p) != len(positions[0]) for p in positions):
            # Cycles (blender/mesh.cpp, sync_mesh_motion) drops the motion of a mesh whose vertex count changes.
            warnings.append(f"Object '{names[key]}': its vertex count changes during the shutter; its deformation "
                            "is not blurred")
        elif _moving(positions):
            deformation[key] = np.stack(positions)
    camera = steps("camera", camera_count) if camera_count else None
    return ShutterMotion(objects, camera if _moving(camera) else None, shutter_curve(render), deformation, warnings)
