"""An independent numpy decoder of SuperSplat's compressed PLY, written from the format's sources (not from
RaySplats' C++): PlayCanvas engine src/scene/gsplat/gsplat-compressed-data.js and splat-transform
src/lib/readers/decompress-ply.ts. Used by native/python/test_compressed_ply.py (the reader and writer against it) and
by ewa_rasterizer.read_splats (the viewer-agreement test's reference scenes)."""
import numpy as np

SH_C0 = 0.28209479177387814
PLY_TYPES = {"float": "<f4", "uint": "<u4", "uchar": "u1", "int": "<i4", "double": "<f8", "ushort": "<u2",
             "short": "<i2", "char": "i1"}


def read_ply_elements(path):
    """{element name: structured numpy array} of a binary little-endian PLY without list properties."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    elements = []
    for line in data[:end].decode("ascii").splitlines():
        words = line.split()
        if words[0] == "format":
            assert words[1] == "binary_little_endian", words
        elif words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property":
            elements[-1][2].append((words[2], PLY_TYPES[words[1]]))
    out, offset = {}, end
    for name, count, properties in elements:
        dtype = np.dtype(properties)
        out[name] = np.frombuffer(data, dtype, count, offset)
        offset += count * dtype.itemsize
    assert offset == len(data), (offset, len(data))
    return out


def unorm(value, bits):
    return (value & ((1 << bits) - 1)).astype(np.float64) / ((1 << bits) - 1)


def decode_compressed(path):
    """Positions, rotations (w x y z, normalised), linear scales, linear opacities, f_dc (n x 3), f_rest (n x 3 x M)
    in float64, decoded from the spec."""
    ply = read_ply_elements(path)
    chunk, vertex = ply["chunk"], ply["vertex"]
    n = len(vertex)
    assert len(chunk) == (n + 255) // 256
    c = np.arange(n) // 256

    def bound(name):
        return chunk[name].astype(np.float64)[c]

    def lerp(a, b, t):
        return a * (1 - t) + b * t

    def unpack_111011(v):
        v = v.astype(np.uint32)
        return unorm(v >> 21, 11), unorm(v >> 11, 10), unorm(v, 11)

    position = np.stack([lerp(bound("min_" + a), bound("max_" + a), t)
                         for a, t in zip("xyz", unpack_111011(vertex["packed_position"]))], axis=1)
    scale = np.exp(np.stack([lerp(bound("min_scale_" + a), bound("max_scale_" + a), t)
                             for a, t in zip("xyz", unpack_111011(vertex["packed_scale"]))], axis=1))
    colour = vertex["packed_color"].astype(np.uint32)
    rgb = [unorm(colour >> 24, 8), unorm(colour >> 16, 8), unorm(colour >> 8, 8)]
    if "min_r" in chunk.dtype.names:
        rgb = [lerp(bound("min_" + a), bound("max_" + a), t) for a, t in zip("rgb", rgb)]
    f_dc = (np.stack(rgb, axis=1) - 0.5) / SH_C0
    opacity = unorm(colour, 8)
    # Smallest three: bits 31..30 the index of the largest of (rot_0, rot_1, rot_2, rot_3) = (w, x, y, z); the other
    # three in index order, each (unorm10 - 0.5) * sqrt(2).
    r = vertex["packed_rotation"].astype(np.uint32)
    small = np.stack([(unorm(r >> s, 10) - 0.5) * np.sqrt(2) for s in (20, 10, 0)], axis=1)
    largest = (r >> 30).astype(np.int64)
    m = np.sqrt(np.maximum(0, 1 - (small ** 2).sum(axis=1)))
    rotation = np.empty((n, 4))
    for k in range(4):
        others = [j for j in range(4) if j != k]
        rows = largest == k
        rotation[rows, k] = m[rows]
        rotation[np.ix_(rows, others)] = small[rows]
    rotation /= np.linalg.norm(rotation, axis=1, keepdims=True)
    f_rest = np.zeros((n, 3, 0))
    if "sh" in ply:
        b = np.stack([ply["sh"][name] for name in ply["sh"].dtype.names], axis=1).astype(np.float64)
        normalised = np.where(b == 0, 0.0, np.where(b == 255, 1.0, (b + 0.5) / 256))
        f_rest = ((normalised - 0.5) * 8).reshape(n, 3, -1)  # channel-major, as INRIA's f_rest
    return {"positions": position, "rotations": rotation, "scales": scale, "opacities": opacity, "f_dc": f_dc,
            "f_rest": f_rest, "chunk": chunk}
