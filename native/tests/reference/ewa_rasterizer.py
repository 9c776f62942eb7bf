"""An independent numpy reference of what every splat viewer draws: the 3D Gaussian Splatting EWA rasterizer.

Written from the 3DGS paper (Kerbl et al. 2023, "3D Gaussian Splatting for Real-Time Radiance Field Rendering",
§4 and §6) and the conventions of its reference CUDA rasterizer (diff-gaussian-rasterization, forward.cu), calling
nothing of RaySplats. Its readers, too, are written from the file formats' specifications (INRIA PLY, antimatter15
.splat, SuperSplat compressed PLY in supersplat_compressed_ply.py), so a reader bug of the project cannot hide here.

Conventions (those of the reference rasterizer):
- Covariance Sigma = R S S^T R^T, R from the unit quaternion (w, x, y, z), S = diag(scale).
- Camera: OpenCV/COLMAP view space (x right, y down, z forward). Gaussians whose centre has z <= near are culled
  (0.2 in the reference, an absolute distance: scenes far smaller than that, such as the 0.17-wide donut, need a
  smaller one).
- 2D covariance Sigma' = J W Sigma W^T J^T with the perspective Jacobian J of (x, y, z) -> (fx x / z, fy y / z) at the
  centre, x/z and y/z clamped to 1.3 tan(fov / 2) (forward.cu computeCov2D), plus 0.3 px^2 on the diagonal (the
  low-pass "dilation").
- Screen radius ceil(3 sqrt(lambda_max(Sigma'))); pixel centres at integer + 0.5 of the image plane [0, W] x [0, H].
- Colour from SH in the direction from the camera centre to the Gaussian centre, + 0.5, clamped at 0 (no upper
  clamp): sRGB display values, composited as they are.
- Sorted front to back by view-space depth of the centre. alpha = min(0.99, opacity exp(power)), power =
  -1/2 d^T Sigma'^-1 d (skipped if power > 0); skipped if alpha < 1/255; a pixel stops before the Gaussian that would
  bring its transmittance below 1e-4. C = sum T_i alpha_i c_i + T bg.
"""
import math
import struct

import numpy as np

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
         1.445305721320277, -0.5900435899266435)

PLY_TYPES = {"float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8", "uchar": "u1", "uint8": "u1",
             "char": "i1", "int8": "i1", "short": "<i2", "int16": "<i2", "ushort": "<u2", "uint16": "<u2",
             "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4"}


class Splats:
    """positions (n, 3), unit quaternions w x y z (n, 4), scales (n, 3), opacities (n,) in [0, 1], and SH as
    (n, coefficients, 3): coefficient 0 is the DC term (colour = 0.5 + SH_C0 f_dc)."""

    def __init__(self, positions, rotations, scales, opacities, sh):
        self.positions = np.ascontiguousarray(positions, np.float32)
        q = np.asarray(rotations, np.float64)
        self.rotations = np.ascontiguousarray(q / np.linalg.norm(q, axis=1, keepdims=True), np.float32)
        self.scales = np.ascontiguousarray(scales, np.float32)
        self.opacities = np.ascontiguousarray(opacities, np.float32)
        self.sh = np.ascontiguousarray(sh, np.float32)

    def __len__(self):
        return len(self.opacities)


def read_inria_ply(path):
    """INRIA 3DGS PLY (binary little endian): properties by name, in any order; opacity is a logit, scales are logs,
    f_rest channel-major (all red coefficients, then green, then blue)."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError(f"{path}: not a PLY file")
        props, count, fmt = [], None, None
        while True:
            line = f.readline().decode("ascii").strip()
            if line == "end_header":
                break
            words = line.split()
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                if words[1] != "vertex":
                    raise ValueError(f"{path}: element {words[1]} before the vertices is not handled here")
                count = int(words[2])
            elif words[0] == "property":
                props.append((words[2], PLY_TYPES[words[1]]))
        if fmt != "binary_little_endian":
            raise ValueError(f"{path}: format {fmt} is not handled here")
        data = np.frombuffer(f.read(count * np.dtype(props).itemsize), dtype=np.dtype(props), count=count)
    names = data.dtype.names
    rest = sorted((n for n in names if n.startswith("f_rest_")), key=lambda n: int(n[7:]))
    coeffs = len(rest) // 3 + 1
    sh = np.zeros((count, coeffs, 3), np.float32)
    for c in range(3):
        sh[:, 0, c] = data[f"f_dc_{c}"]
        for k in range(coeffs - 1):
            sh[:, 1 + k, c] = data[rest[c * (coeffs - 1) + k]]
    col = lambda *keys: np.stack([data[k].astype(np.float64) for k in keys], axis=1)  # noqa: E731
    return Splats(col("x", "y", "z"), col("rot_0", "rot_1", "rot_2", "rot_3"),
                  np.exp(col("scale_0", "scale_1", "scale_2")),
                  1.0 / (1.0 + np.exp(-data["opacity"].astype(np.float64))), sh)


def read_dot_splat(path):
    """antimatter15 .splat: 32 bytes a splat, position 3 x f32, scale 3 x f32 (linear), RGBA 4 x u8 (display colour
    and opacity), rotation 4 x u8 (w x y z, (v - 128) / 128)."""
    raw = np.fromfile(path, dtype=np.dtype([("p", "<f4", 3), ("s", "<f4", 3), ("c", "u1", 4), ("q", "u1", 4)]))
    rgba = raw["c"].astype(np.float64) / 255.0
    sh = ((rgba[:, :3] - 0.5) / SH_C0)[:, None, :]
    return Splats(raw["p"], (raw["q"].astype(np.float64) - 128.0) / 128.0, raw["s"], rgba[:, 3], sh)


def read_supersplat_compressed_ply(path):
    """SuperSplat's compressed PLY (chunk bounds and packed vertices), by the independent decoder in
    supersplat_compressed_ply.py."""
    from supersplat_compressed_ply import decode_compressed
    d = decode_compressed(path)
    n, rest = len(d["opacities"]), d["f_rest"]
    sh = np.zeros((n, 1 + rest.shape[2], 3))
    sh[:, 0] = d["f_dc"]
    sh[:, 1:] = np.transpose(rest, (0, 2, 1))  # f_rest is (n, channel, coefficient)
    return Splats(d["positions"], d["rotations"], d["scales"], d["opacities"], sh)


def read_splats(path):
    if path.endswith(".ply"):
        with open(path, "rb") as f:
            header = f.read(4096)
        if b"\nelement chunk " in header:
            return read_supersplat_compressed_ply(path)
        return read_inria_ply(path)
    if path.endswith(".splat"):
        return read_dot_splat(path)
    raise ValueError(f"{path}: no reference reader for this format")


def quaternion_to_matrix(q):
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def sh_to_display(sh, dirs):
    """Reference 3DGS computeColorFromSH: the real SH basis with its sign conventions, + 0.5, clamped at 0."""
    x, y, z = dirs[:, 0:1], dirs[:, 1:2], dirs[:, 2:3]
    coeffs = sh.shape[1]
    result = SH_C0 * sh[:, 0]
    if coeffs > 1:
        result = result - SH_C1 * y * sh[:, 1] + SH_C1 * z * sh[:, 2] - SH_C1 * x * sh[:, 3]
    if coeffs > 4:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        result = (result + SH_C2[0] * xy * sh[:, 4] + SH_C2[1] * yz * sh[:, 5] +
                  SH_C2[2] * (2.0 * zz - xx - yy) * sh[:, 6] + SH_C2[3] * xz * sh[:, 7] +
                  SH_C2[4] * (xx - yy) * sh[:, 8])
    if coeffs > 9:
        result = (result + SH_C3[0] * y * (3.0 * xx - yy) * sh[:, 9] + SH_C3[1] * xy * z * sh[:, 10] +
                  SH_C3[2] * y * (4.0 * zz - xx - yy) * sh[:, 11] +
                  SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh[:, 12] +
                  SH_C3[4] * x * (4.0 * zz - xx - yy) * sh[:, 13] + SH_C3[5] * z * (xx - yy) * sh[:, 14] +
                  SH_C3[6] * x * (xx - 3.0 * yy) * sh[:, 15])
    return np.maximum(result + 0.5, 0.0)


def rasterize(splats, world_to_view, fx, fy, width, height, background=(0.0, 0.0, 0.0), near=0.2):
    """The display-space image (height, width, 3) of `splats` seen by a pinhole camera. world_to_view: 4x4 matrix
    into OpenCV view space (x right, y down, z forward); principal point at the image centre."""
    W = np.asarray(world_to_view, np.float64)
    p_world = splats.positions.astype(np.float64)
    p_view = p_world @ W[:3, :3].T + W[:3, 3]
    keep = p_view[:, 2] > near
    idx = np.nonzero(keep)[0]
    pv = p_view[idx]
    R = quaternion_to_matrix(splats.rotations[idx].astype(np.float64))
    M = R * splats.scales[idx].astype(np.float64)[:, None, :]  # R S
    cov3 = M @ np.transpose(M, (0, 2, 1))
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    tz = pv[:, 2]
    tx = np.clip(pv[:, 0] / tz, -1.3 * tan_x, 1.3 * tan_x) * tz
    ty = np.clip(pv[:, 1] / tz, -1.3 * tan_y, 1.3 * tan_y) * tz
    J = np.zeros((len(idx), 2, 3))
    J[:, 0, 0] = fx / tz
    J[:, 0, 2] = -fx * tx / (tz * tz)
    J[:, 1, 1] = fy / tz
    J[:, 1, 2] = -fy * ty / (tz * tz)
    T = J @ W[:3, :3]
    cov2 = T @ cov3 @ np.transpose(T, (0, 2, 1))
    a = cov2[:, 0, 0] + 0.3
    b = cov2[:, 0, 1]
    c = cov2[:, 1, 1] + 0.3
    det = a * c - b * b
    ok = det > 0
    mid = 0.5 * (a + c)
    lam = mid + np.sqrt(np.maximum(0.1, mid * mid - det))
    radius = np.ceil(3.0 * np.sqrt(lam))
    # Image-plane centre: ndc -> pixel as forward.cu's ndc2Pix, whose pixel centres are the integers; here the
    # plane runs over [0, W] with pixel centres at integer + 0.5, the same points.
    u = fx * pv[:, 0] / tz + 0.5 * width
    v = fy * pv[:, 1] / tz + 0.5 * height
    campos = -W[:3, :3].T @ W[:3, 3]
    dirs = p_world[idx] - campos
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    colors = sh_to_display(splats.sh[idx].astype(np.float64), dirs)
    opac = splats.opacities[idx].astype(np.float64)
    inv_a, inv_b, inv_c = c / np.where(ok, det, 1), -b / np.where(ok, det, 1), a / np.where(ok, det, 1)

    image = np.zeros((height, width, 3))
    trans = np.ones((height, width))
    done = np.zeros((height, width), bool)
    for k in np.argsort(tz, kind="stable"):
        if not ok[k]:
            continue
        x0, x1 = int(max(0, math.floor(u[k] - radius[k]))), int(min(width, math.ceil(u[k] + radius[k]) + 1))
        y0, y1 = int(max(0, math.floor(v[k] - radius[k]))), int(min(height, math.ceil(v[k] + radius[k]) + 1))
        if x0 >= x1 or y0 >= y1:
            continue
        dx = (np.arange(x0, x1) + 0.5 - u[k])[None, :]
        dy = (np.arange(y0, y1) + 0.5 - v[k])[:, None]
        power = -0.5 * (inv_a[k] * dx * dx + inv_c[k] * dy * dy) - inv_b[k] * dx * dy
        alpha = np.minimum(0.99, opac[k] * np.exp(power))
        alpha[(power > 0) | (alpha < 1.0 / 255.0)] = 0.0
        t = trans[y0:y1, x0:x1]
        d = done[y0:y1, x0:x1]
        alpha[d] = 0.0
        stop = (t * (1.0 - alpha) < 1e-4) & (alpha > 0)
        alpha[stop] = 0.0
        d |= stop
        image[y0:y1, x0:x1] += (alpha * t)[..., None] * colors[k]
        t *= 1.0 - alpha
    return image + trans[..., None] * np.asarray(background, np.float64)


def srgb_to_linear(c):
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c):
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.maximum(c, 0.0031308) ** (1.0 / 2.4) - 0.055)


def psnr(reference, test):
    """PSNR (dB) of two display images, each clamped to [0, 1] as a display shows it."""
    mse = np.mean((np.clip(reference, 0, 1) - np.clip(test, 0, 1)) ** 2)
    return float("inf") if mse == 0 else 10.0 * math.log10(1.0 / mse)
