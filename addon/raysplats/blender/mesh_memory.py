# Where a mesh's bytes go: the size of each of its layers (the built-in vertex, edge, corner and face arrays, every
# generic attribute, UV maps), for the import memory benchmark (examples/benchmark_import_memory.py) and the test
# that pins the Gaussian mesh's layout (blender_tests/test_import_memory.py). Any mesh, not only Gaussian ones. And
# the process's resident memory and its peak, which both of them measure an import by.
from . import compat


def process_memory_bytes(field):
    """A memory figure of this process from /proc/self/status (Linux), in bytes: "VmRSS" (resident now), "VmHWM"
    (peak resident)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    raise RuntimeError(f"/proc/self/status has no {field}")


def reset_peak_memory():
    """Resets VmHWM to the current resident memory (Linux 4.0+); False where that is not allowed."""
    try:
        with open("/proc/self/clear_refs", "w") as clear_refs:
            clear_refs.write("5")
        return True
    except OSError:
        return False

# Bytes per element of each generic attribute type.
ATTRIBUTE_TYPE_BYTES = {"FLOAT": 4, "INT": 4, "FLOAT_VECTOR": 12, "FLOAT_COLOR": 16, "BYTE_COLOR": 4, "STRING": 0,
                        "BOOLEAN": 1, "FLOAT2": 8, "INT8": 1, "INT32_2D": 8, "QUATERNION": 16, "FLOAT4X4": 64,
                        "INT16_2D": 4, "FLOAT4": 16}
_DOMAIN_OF = {"vertices": "POINT", "edges": "EDGE", "loops": "CORNER", "polygons": "FACE"}


def _stride(elements):
    """Bytes from one element of a bpy collection to the next in Blender's array (0 for fewer than two)."""
    return elements[1].as_pointer() - elements[0].as_pointer() if len(elements) > 1 else 0


def layer_sizes(mesh):
    """{layer name: (domain, bytes)} of `mesh`: "vertices", "edges", "corners" and "faces" are the built-in arrays
    (Blender 3.4's MVert/MEdge/MLoop/MPoly structs, or from 3.6 on the position, edge vertex, corner vertex arrays and
    the face offsets), then every generic attribute (Blender 4.x lists its built-in ones, such as ".corner_edge" and
    ".select_vert", among them; the ones counted as built-in arrays above are left out) and each UV map that is not
    one (3.4: MLoopUV)."""
    sizes = {}
    primary = set()
    for key, name in (("vertices", "vertices"), ("edges", "edges"), ("loops", "corners"), ("polygons", "faces")):
        elements = getattr(mesh, key)
        count = len(elements)
        stride = _stride(elements)
        if key == "polygons" and compat.MESH_TOPOLOGY_IN_INT32_ARRAYS:
            sizes[name] = (_DOMAIN_OF[key], 4 * (count + 1) if count else 0)  # face offsets, one past the last
        else:
            sizes[name] = (_DOMAIN_OF[key], stride * count)
    if compat.MESH_POSITIONS_ARE_AN_ATTRIBUTE:
        primary.add("position")
    if compat.MESH_TOPOLOGY_IN_INT32_ARRAYS:
        primary.update((compat.MESH_CORNER_VERTEX_ATTRIBUTE, ".edge_verts"))
    for attribute in mesh.attributes:
        if attribute.name in primary:
            continue
        sizes[attribute.name] = (attribute.domain, ATTRIBUTE_TYPE_BYTES.get(attribute.data_type, 0)
                                 * len(attribute.data))
    if not compat.UV_MAPS_ARE_ATTRIBUTES:
        for uv_layer in mesh.uv_layers:
            sizes[uv_layer.name] = ("CORNER", _stride(uv_layer.data) * len(uv_layer.data))
    return sizes


def mesh_bytes(mesh):
    """The total of layer_sizes(mesh)."""
    return sum(size for _, size in layer_sizes(mesh).values())
