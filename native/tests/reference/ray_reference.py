"""An experiment beside the EWA reference (not a replacement): the same scene drawn per pixel with either footprint
and either order, to attribute the difference between RaySplats and the EWA rasterizer to its causes.

    footprint "ewa": the EWA-projected 2D Gaussian of ewa_rasterizer.rasterize (its Jacobian clamp, 0.3 px^2
                     dilation, ceil(3 sqrt(lambda_max)) square of pixels), unchanged;
    footprint "ray": the exact maximum response of the 3D Gaussian along the pixel's ray, exp(-1/2 min_t |y(t)|^2)
                     with y = S^-1 R^T (o + t d - m) (Mahalanobis radius cut at min(3, sqrt(2 ln(255 opacity)))), as
                     RaySplats' volumetric mode evaluates it; no dilation, no clamp;
    order "centre":  one global sort by the view depth of the centre (what rasterizers do);
    order "ray":     per pixel, by the depth of the point of maximum response on the ray (what RaySplats does);
    order "ray_centre": per pixel, by the depth of the centre's projection onto the ray (an experiment).

Everything else is the rasterizer's convention: alpha = min(0.99, opacity G), cut below 1/255, colour from SH in the
direction camera -> centre clamped at 0, display-space compositing, Gaussians with centre depth <= near culled
(`cull="centre"`) or, as the engine does, hits whose maximum-response point is nearer than `near` (`cull="hit"`),
compositing stopped before (`stop="before"`, the rasterizer) or after (`stop="after"`, the engine) the Gaussian that
takes the transmittance below 1e-4.

footprint="ewa", order="centre", cull="centre", stop="before" reproduces ewa_rasterizer.rasterize (to float
rounding); footprint="ray", order="ray", cull="hit", stop="after" is RaySplats' volumetric model. Pure numpy, calling
nothing of RaySplats. Computed densely per tile of pixels (each Gaussian against every pixel of each tile its
bounding box overlaps): slow, meant for 640 x 480 and scenes under 100 k Gaussians.
"""
import numpy as np

import ewa_rasterizer as ewa


def _screen_boxes_ray(pv, axes, scales, radius, fx, fy, width, height):
    """Pixel bounding boxes (x0, x1, y0, y1), half-open, of each Gaussian's support ellipsoid: the projections of the
    8 corners of its oriented box (the whole image when a corner is not in front of the camera)."""
    n = len(pv)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64)
    half = axes * (scales * radius[:, None])[:, None, :]  # columns: the box's half axes
    corners = pv[:, None, :] + np.einsum("kj,nij->nki", signs, half)
    z = corners[..., 2]
    front = (z > 1e-9).all(axis=1)
    zs = np.where(z > 1e-9, z, 1.0)
    u = fx * corners[..., 0] / zs + 0.5 * width
    v = fy * corners[..., 1] / zs + 0.5 * height
    x0 = np.where(front, np.floor(u.min(axis=1) - 0.5), 0)
    x1 = np.where(front, np.ceil(u.max(axis=1) - 0.5) + 1, width)
    y0 = np.where(front, np.floor(v.min(axis=1) - 0.5), 0)
    y1 = np.where(front, np.ceil(v.max(axis=1) - 0.5) + 1, height)
    out = np.stack([np.clip(x0, 0, width), np.clip(x1, 0, width), np.clip(y0, 0, height), np.clip(y1, 0, height)], 1)
    return out.astype(np.int64) if n else np.zeros((0, 4), np.int64)


def render(splats, world_to_view, fx, fy, width, height, near=0.2, footprint="ray", order="ray", cull="hit",
           stop="after", tile=32, stats=None, jacobian_clamp=1.3, dilation=0.3, ewa_mahalanobis_cut=False):
    """The display image (height, width, 3) of `splats` (black background), pinhole camera as
    ewa_rasterizer.rasterize. `stats`, a dict, receives per-pixel maps: "max_extent" (the largest s_max / depth of
    the Gaussians that reach the pixel with alpha >= 1/255). Experiment knobs of the EWA footprint: `jacobian_clamp`
    (None: no clamp of x/z, y/z), `dilation` (px^2), `ewa_mahalanobis_cut` (also cut where the 2D Mahalanobis
    radius exceeds the ray footprint's support radius, as the engine's ellipsoid)."""
    W = np.asarray(world_to_view, np.float64)
    p_world = splats.positions.astype(np.float64)
    pv_all = p_world @ W[:3, :3].T + W[:3, 3]
    n_all = len(pv_all)
    keep = pv_all[:, 2] > near if cull == "centre" else np.ones(n_all, bool)
    idx = np.nonzero(keep)[0]
    pv = pv_all[idx]
    R = W[:3, :3] @ ewa.quaternion_to_matrix(splats.rotations[idx].astype(np.float64))  # axes in view space
    s = splats.scales[idx].astype(np.float64)
    s = np.maximum(s, 1e-6 * s.max(axis=1, keepdims=True))  # the engine's floor of the smallest axis
    opac = np.clip(splats.opacities[idx].astype(np.float64), 0, 1)
    campos = -W[:3, :3].T @ W[:3, 3]
    dirs = p_world[idx] - campos
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    colors = ewa.sh_to_display(splats.sh[idx].astype(np.float64), dirs)
    n = len(idx)

    with np.errstate(divide="ignore", invalid="ignore"):
        support = np.minimum(9.0, 2.0 * np.log(255.0 * opac))
    support = np.where(np.isfinite(support), support, -1.0)
    A = np.transpose(R, (0, 2, 1)) / s[:, :, None]  # rows: S^-1 R^T (view -> canonical)
    pu = -np.einsum("nij,nj->ni", A, pv)             # canonical coordinates of the camera centre
    pp = (pu * pu).sum(axis=1)

    # EWA quantities, exactly as ewa_rasterizer.rasterize computes them.
    tz = np.where(pv[:, 2] != 0, pv[:, 2], 1e-30)
    M = R * s[:, None, :]
    cov3 = M @ np.transpose(M, (0, 2, 1))  # view space already
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    lim = np.inf if jacobian_clamp is None else jacobian_clamp
    tx = np.clip(pv[:, 0] / tz, -lim * tan_x, lim * tan_x) * tz
    ty = np.clip(pv[:, 1] / tz, -lim * tan_y, lim * tan_y) * tz
    J = np.zeros((n, 2, 3))
    J[:, 0, 0] = fx / tz
    J[:, 0, 2] = -fx * tx / (tz * tz)
    J[:, 1, 1] = fy / tz
    J[:, 1, 2] = -fy * ty / (tz * tz)
    cov2 = J @ cov3 @ np.transpose(J, (0, 2, 1))
    a, b, c = cov2[:, 0, 0] + dilation, cov2[:, 0, 1], cov2[:, 1, 1] + dilation
    det = a * c - b * b
    ewa_ok = (det > 0) & (pv[:, 2] > 0)
    mid = 0.5 * (a + c)
    radius_px = np.ceil(3.0 * np.sqrt(mid + np.sqrt(np.maximum(0.1, mid * mid - det))))
    u_c = fx * pv[:, 0] / tz + 0.5 * width
    v_c = fy * pv[:, 1] / tz + 0.5 * height
    dsafe = np.where(ewa_ok, det, 1.0)
    inv_a, inv_b, inv_c = c / dsafe, -b / dsafe, a / dsafe

    if footprint == "ray":
        boxes = _screen_boxes_ray(pv, R, s, np.sqrt(np.maximum(support, 0)), fx, fy, width, height)
        live = support > 0
    else:
        boxes = np.stack([np.maximum(0, np.floor(u_c - radius_px)), np.minimum(width, np.ceil(u_c + radius_px) + 1),
                          np.maximum(0, np.floor(v_c - radius_px)), np.minimum(height, np.ceil(v_c + radius_px) + 1)],
                         1).astype(np.int64)
        live = ewa_ok
    centre_rank = np.argsort(np.argsort(pv[:, 2], kind="stable"), kind="stable")
    extent = s.max(axis=1) / np.maximum(pv[:, 2], 1e-30)

    image = np.zeros((height, width, 3))
    if stats is not None:
        stats["max_extent"] = np.zeros((height, width))
    for ty0 in range(0, height, tile):
        for tx0 in range(0, width, tile):
            ty1, tx1 = min(height, ty0 + tile), min(width, tx0 + tile)
            sel = np.nonzero(live & (boxes[:, 0] < tx1) & (boxes[:, 1] > tx0) & (boxes[:, 2] < ty1) &
                             (boxes[:, 3] > ty0))[0]
            if len(sel) == 0:
                continue
            sel = sel[np.argsort(centre_rank[sel], kind="stable")]
            px, py = np.meshgrid(np.arange(tx0, tx1), np.arange(ty0, ty1))
            px, py = px.ravel(), py.ravel()
            d = np.stack([(px + 0.5 - 0.5 * width) / fx, (py + 0.5 - 0.5 * height) / fy, np.ones(len(px))])  # (3, P)
            if footprint == "ray" or order != "centre" or cull == "hit":
                du = A[sel] @ d                                          # (G, 3, P)
                pd = np.einsum("gi,gip->gp", pu[sel], du)
                dd = np.einsum("gip,gip->gp", du, du)
                t = -pd / dd                                             # view depth of the maximum (d has z = 1)
            if footprint == "ray":
                dist2 = np.maximum(pp[sel][:, None] + pd * t, 0.0)            # |pu + t du|^2 = pp - pd^2 / dd
                alpha = np.minimum(0.99, opac[sel][:, None] * np.exp(-0.5 * dist2))
                alpha[dist2 > support[sel][:, None]] = 0.0
            else:
                dx = px[None, :] + 0.5 - u_c[sel][:, None]
                dy = py[None, :] + 0.5 - v_c[sel][:, None]
                power = -0.5 * (inv_a[sel][:, None] * dx * dx + inv_c[sel][:, None] * dy * dy) - \
                    inv_b[sel][:, None] * dx * dy
                alpha = np.minimum(0.99, opac[sel][:, None] * np.exp(power))
                alpha[power > 0] = 0.0
                if ewa_mahalanobis_cut:
                    alpha[-2.0 * power > support[sel][:, None]] = 0.0
                inside = ((px[None, :] >= boxes[sel, 0:1]) & (px[None, :] < boxes[sel, 1:2]) &
                          (py[None, :] >= boxes[sel, 2:3]) & (py[None, :] < boxes[sel, 3:4]))
                alpha[~inside] = 0.0
            alpha[alpha < 1.0 / 255.0] = 0.0
            if cull == "hit":
                alpha[t < near] = 0.0
            colour_index = np.broadcast_to(sel[:, None], alpha.shape)
            if order in ("ray", "ray_centre"):
                # "ray_centre": per ray, by the depth of the centre's projection onto the ray (an experiment).
                key = t if order == "ray" else (pv[sel] @ d) / (d * d).sum(axis=0)[None, :]
                o = np.argsort(np.where(alpha > 0, key, np.inf), axis=0, kind="stable")
                alpha = np.take_along_axis(alpha, o, axis=0)
                colour_index = np.take_along_axis(colour_index, o, axis=0)
            trans_after = np.cumprod(1.0 - alpha, axis=0)
            trans_before = np.vstack([np.ones((1, alpha.shape[1])), trans_after[:-1]])
            if stop == "before":
                used = trans_after >= 1e-4
            else:
                used = trans_before >= 1e-4
            weight = trans_before * alpha * used
            rgb = np.einsum("gp,gpc->pc", weight, colors[colour_index])
            image[ty0:ty1, tx0:tx1] = rgb.reshape(ty1 - ty0, tx1 - tx0, 3)
            if stats is not None:
                stats["max_extent"][ty0:ty1, tx0:tx1] = np.max(
                    np.where(alpha > 0, extent[colour_index], 0.0), axis=0).reshape(ty1 - ty0, tx1 - tx0)
    return image
