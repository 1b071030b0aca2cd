"""The renderer's compiled kernels (numba): rasterise, shade, blur, finish.

Chosen by measurement (docs/performance-history.md, "render"): Pillow's polygon fill plus numpy's
per-pixel passes took 32 ms for a clear 800 x 600 frame on one core here, most of it in
whole-frame numpy passes that each read and write the frame again; every condition would
have added more. These loops visit each pixel once per stage in compiled code, single
threaded (``parallel`` is off: one core is the budget, and the bytes must not depend on how
work is split). No ``fastmath``: IEEE arithmetic in a fixed order, so the same state gives the
same bytes. The kernels are compiled on first use and cached beside this file
(``cache=True``; NUMBA_CACHE_DIR elsewhere).

Conventions: camera coordinates X right, Y up, Z forward; a pixel (column c, row r) has its
centre at u = c + 0.5, v = r + 0.5; a polygon covers the pixels whose centres lie inside it
(left and top edges included), so abutting polygons never share a pixel and never leave a gap.
"""

from __future__ import annotations

import math

import numba
import numpy as np

MAX_VERTICES = 8
"""A quad cut by the near plane has at most 5 corners; room to spare."""
TIE = 1e-6
"""Relative depth within which the later of two faces wins (a decal on its surface)."""

_jit = numba.njit(cache=True, nogil=True, fastmath=False, error_model="numpy")


@_jit
def _clip_project(quad, near, focal, half_w, half_h, out):  # type: ignore[no-untyped-def]
    """``quad`` (4, 3) cut at z = near (Sutherland-Hodgman) and projected into ``out``
    (MAX_VERTICES, 2) pixel coordinates; the number of corners (0 when behind)."""
    count = 0
    for i in range(4):
        ax, ay, az = quad[i, 0], quad[i, 1], quad[i, 2]
        j = (i + 1) % 4
        bx, by, bz = quad[j, 0], quad[j, 1], quad[j, 2]
        a_in = az > near
        if a_in:
            out[count, 0] = focal * ax / az + half_w
            out[count, 1] = -focal * ay / az + half_h
            count += 1
        if a_in != (bz > near):
            t = (near - az) / (bz - az)
            x = ax + t * (bx - ax)
            y = ay + t * (by - ay)
            out[count, 0] = focal * x / near + half_w
            out[count, 1] = -focal * y / near + half_h
            count += 1
    return count


@_jit
def _span(poly, count, yc):  # type: ignore[no-untyped-def]
    """Left and right u where row centre ``yc`` crosses the convex polygon (left > right:
    it does not)."""
    left = 1e300
    right = -1e300
    for i in range(count):
        x0, y0 = poly[i, 0], poly[i, 1]
        j = (i + 1) % count
        x1, y1 = poly[j, 0], poly[j, 1]
        if (y0 <= yc < y1) or (y1 <= yc < y0):
            x = x0 + (yc - y0) * (x1 - x0) / (y1 - y0)
            left = min(left, x)
            right = max(right, x)
    return left, right


@_jit
def _plane(quad, focal, half_w, half_h):  # type: ignore[no-untyped-def]
    """1 / z of the quad's plane as a u + b v + c; (0, 0, 0) when the plane holds the eye."""
    ux = quad[2, 0] - quad[0, 0]
    uy = quad[2, 1] - quad[0, 1]
    uz = quad[2, 2] - quad[0, 2]
    vx = quad[3, 0] - quad[1, 0]
    vy = quad[3, 1] - quad[1, 1]
    vz = quad[3, 2] - quad[1, 2]
    nx = uy * vz - uz * vy
    ny = uz * vx - ux * vz
    nz = ux * vy - uy * vx
    cx = (quad[0, 0] + quad[1, 0] + quad[2, 0] + quad[3, 0]) / 4.0
    cy = (quad[0, 1] + quad[1, 1] + quad[2, 1] + quad[3, 1]) / 4.0
    cz = (quad[0, 2] + quad[1, 2] + quad[2, 2] + quad[3, 2]) / 4.0
    d = nx * cx + ny * cy + nz * cz
    size = math.sqrt(nx * nx + ny * ny + nz * nz)
    if size < 1e-12 or abs(d) < 1e-9 * size:
        return 0.0, 0.0, 0.0
    a = nx / (focal * d)
    b = -ny / (focal * d)
    c = (nz - nx * half_w / focal + ny * half_h / focal) / d
    return a, b, c


@_jit
def rasterise(quads, background, width, height, focal, near, ids, inverse_z, row_begin, row_end):  # type: ignore[no-untyped-def]
    """Fill rows ``row_begin`` to ``row_end`` (exclusive) of ``ids`` (face index + 1; 0
    nothing) and ``inverse_z`` (1 / z) from ``quads`` (n, 4, 3) in camera coordinates, in
    their order: background faces (the terrain) paint over each other and lie behind
    everything; other faces win where they are nearer, or within ``TIE`` of the nearest (so
    the later of two coplanar faces shows). A pixel depends on its own row alone, so bands of
    rows filled apart (in threads) give the frame filled whole."""
    ids[row_begin:row_end, :] = 0
    inverse_z[row_begin:row_end, :] = 0.0
    half_w = width / 2.0
    half_h = height / 2.0
    poly = np.empty((MAX_VERTICES, 2))
    for f in range(quads.shape[0]):
        quad = quads[f]
        a, b, c = _plane(quad, focal, half_w, half_h)
        if a == 0.0 and b == 0.0 and c == 0.0:
            continue
        count = _clip_project(quad, near, focal, half_w, half_h, poly)
        if count < 3:
            continue
        top = 1e300
        bottom = -1e300
        for i in range(count):
            top = min(top, poly[i, 1])
            bottom = max(bottom, poly[i, 1])
        r0 = max(math.ceil(top - 0.5), row_begin)
        r1 = min(math.ceil(bottom - 0.5), row_end)
        back = background[f]
        for r in range(r0, r1):
            yc = r + 0.5
            left, right = _span(poly, count, yc)
            if left > right:
                continue
            c0 = max(math.ceil(left - 0.5), 0)
            c1 = min(math.ceil(right - 0.5), width)
            for col in range(c0, c1):
                iz = a * (col + 0.5) + b * yc + c
                current = ids[r, col]
                scene = current != 0 and not background[current - 1]
                if scene and (back or iz < inverse_z[r, col] * (1.0 - TIE)):
                    continue
                ids[r, col] = f + 1
                inverse_z[r, col] = iz


@_jit
def coverage(quads, objects, count, width, height, focal, near, pixels):  # type: ignore[no-untyped-def]
    """Pixels each object would cover with nothing in front of it: ``pixels[k]`` for the
    faces whose ``objects`` entry is k (faces of one object consecutive; -1: none)."""
    stamp = np.full((height, width), -1, dtype=np.int32)
    half_w = width / 2.0
    half_h = height / 2.0
    poly = np.empty((MAX_VERTICES, 2))
    for k in range(count):
        pixels[k] = 0
    for f in range(quads.shape[0]):
        k = objects[f]
        if k < 0:
            continue
        n = _clip_project(quads[f], near, focal, half_w, half_h, poly)
        if n < 3:
            continue
        top = 1e300
        bottom = -1e300
        for i in range(n):
            top = min(top, poly[i, 1])
            bottom = max(bottom, poly[i, 1])
        r0 = max(math.ceil(top - 0.5), 0)
        r1 = min(math.ceil(bottom - 0.5), height)
        for r in range(r0, r1):
            left, right = _span(poly, n, r + 0.5)
            if left > right:
                continue
            c0 = max(math.ceil(left - 0.5), 0)
            c1 = min(math.ceil(right - 0.5), width)
            for col in range(c0, c1):
                if stamp[r, col] != k:
                    stamp[r, col] = k
                    pixels[k] += 1


@_jit
def mask(quads, width, height, focal, near, out):  # type: ignore[no-untyped-def]
    """Set ``out`` to 1 where any of ``quads`` covers a pixel (cast shadows on the ground)."""
    out[:, :] = 0
    half_w = width / 2.0
    half_h = height / 2.0
    poly = np.empty((MAX_VERTICES, 2))
    for f in range(quads.shape[0]):
        n = _clip_project(quads[f], near, focal, half_w, half_h, poly)
        if n < 3:
            continue
        top = 1e300
        bottom = -1e300
        for i in range(n):
            top = min(top, poly[i, 1])
            bottom = max(bottom, poly[i, 1])
        r0 = max(math.ceil(top - 0.5), 0)
        r1 = min(math.ceil(bottom - 0.5), height)
        for r in range(r0, r1):
            left, right = _span(poly, n, r + 0.5)
            if left > right:
                continue
            c0 = max(math.ceil(left - 0.5), 0)
            c1 = min(math.ceil(right - 0.5), width)
            for col in range(c0, c1):
                out[r, col] = 1


@_jit
def shade(  # type: ignore[no-untyped-def]
    ids,
    inverse_z,
    focal,
    albedo,
    normals,
    emissive,
    receives,
    objects,
    texture,
    tex_origin,
    tex_u,
    tex_v,
    snow_masks,
    camera,
    axes,
    sun,
    direct,
    ambient,
    shadow,
    lamp,
    lamp_axis,
    lamp_candela,
    lamp_width,
    extinction,
    airlight,
    sky,
    out,
    pixels,
    snowed,
    boxes,
    row_begin,
    row_end,
):
    """The light each pixel receives from what it shows, in the frame's units (255: a white
    surface under the clear-noon light): albedo times (ambient + direct sun * cos * unshadowed
    + headlight), seen through the air (extinction, airlight); the sky row by row where
    nothing is. Per labelled object ``k`` (``objects``), its pixels, those under snow and its
    box (left, top, right, bottom) are counted into ``pixels``, ``snowed``, ``boxes``.

    Faces' arrays are indexed by id (row 0: nothing). ``camera`` is the eye in world
    coordinates, ``axes`` rows its right, up and forward vectors; ``normals`` face the
    camera. A textured face (``texture`` >= 0) is a balise top: its (u, v) in [0, 1) pick a
    cell of ``snow_masks[texture]``, and a cell under snow shows snow.

    Only rows ``row_begin`` to ``row_end`` (exclusive): bands shaded apart, each with its own
    counts and boxes, summed and spanned after, give the frame shaded whole."""
    height, width = ids.shape
    half_w = width / 2.0
    half_h = height / 2.0
    beam = 2.0 / (lamp_width * lamp_width)
    # beyond this the headlights add less than 0.2 % of the daylight (under 1/2 DN) head-on
    daylight = min(ambient[0], ambient[1], ambient[2])
    lamp_reach = math.sqrt(lamp_candela / (0.002 * daylight)) + 2.0 if daylight > 0 else 1e300
    mask_u = snow_masks.shape[1]
    mask_v = snow_masks.shape[2]
    for r in range(row_begin, row_end):
        yr = -(r + 0.5 - half_h) / focal
        for col in range(width):
            face = ids[r, col]
            if face == 0:
                out[r, col, 0] = sky[r, 0]
                out[r, col, 1] = sky[r, 1]
                out[r, col, 2] = sky[r, 2]
                continue
            xr = (col + 0.5 - half_w) / focal
            length = math.sqrt(xr * xr + yr * yr + 1.0)
            distance = length / inverse_z[r, col]
            # the ray in world coordinates, and the point it meets
            wx = (xr * axes[0, 0] + yr * axes[1, 0] + axes[2, 0]) / length
            wy = (xr * axes[0, 1] + yr * axes[1, 1] + axes[2, 1]) / length
            wz = (xr * axes[0, 2] + yr * axes[1, 2] + axes[2, 2]) / length
            px = camera[0] + distance * wx
            py = camera[1] + distance * wy
            pz = camera[2] + distance * wz
            nx, ny, nz = normals[face, 0], normals[face, 1], normals[face, 2]
            k = objects[face]
            red, green, blue = albedo[face, 0], albedo[face, 1], albedo[face, 2]
            under_snow = False
            t = texture[face]
            if t >= 0:
                qx = px - tex_origin[face, 0]
                qy = py - tex_origin[face, 1]
                qz = pz - tex_origin[face, 2]
                u = qx * tex_u[face, 0] + qy * tex_u[face, 1] + qz * tex_u[face, 2]
                v = qx * tex_v[face, 0] + qy * tex_v[face, 1] + qz * tex_v[face, 2]
                iu = min(max(int(u * mask_u), 0), mask_u - 1)
                iv = min(max(int(v * mask_v), 0), mask_v - 1)
                if snow_masks[t, iu, iv]:
                    under_snow = True
                    red, green, blue = 238.0, 240.0, 245.0
            # light: sky, sun (unless in a cast shadow), headlight
            cos_sun = nx * sun[0] + ny * sun[1] + nz * sun[2]
            sunlit = cos_sun if cos_sun > 0.0 else 0.0
            if receives[face] and shadow[r, col]:
                sunlit = 0.0
            lr = ambient[0] + direct[0] * sunlit
            lg = ambient[1] + direct[1] * sunlit
            lb = ambient[2] + direct[2] * sunlit
            if lamp_candela > 0.0 and distance < lamp_reach:
                lx = px - lamp[0]
                ly = py - lamp[1]
                lz = pz - lamp[2]
                ahead = lx * lamp_axis[0] + ly * lamp_axis[1] + lz * lamp_axis[2]
                facing = -(lx * nx + ly * ny + lz * nz)
                if ahead > 0.0 and facing > 0.0:
                    d2 = lx * lx + ly * ly + lz * lz
                    d = math.sqrt(d2)
                    # the beam: I0 / (1 + (angle / width)^2)^2, the angle from its cosine
                    off = (1.0 - ahead / d) * beam + 1.0
                    e = lamp_candela * facing / (off * off * d2 * d)
                    lr += e
                    lg += e
                    lb += e * 0.92
            red = red * lr + emissive[face, 0]
            green = green * lg + emissive[face, 1]
            blue = blue * lb + emissive[face, 2]
            clear = math.exp(-distance * extinction)
            out[r, col, 0] = red * clear + airlight[0] * (1.0 - clear)
            out[r, col, 1] = green * clear + airlight[1] * (1.0 - clear)
            out[r, col, 2] = blue * clear + airlight[2] * (1.0 - clear)
            if k >= 0:
                pixels[k] += 1
                if under_snow:
                    snowed[k] += 1
                if col < boxes[k, 0]:
                    boxes[k, 0] = col
                if r < boxes[k, 1]:
                    boxes[k, 1] = r
                if col > boxes[k, 2]:
                    boxes[k, 2] = col
                if r > boxes[k, 3]:
                    boxes[k, 3] = r


@_jit
def motion_blur(image, inverse_z, focus_u, focus_v, per_inverse_z, out):  # type: ignore[no-untyped-def]
    """Each pixel averaged along its image motion during the exposure: a point at depth z
    moves away from the focus of expansion by (p - focus) * ``per_inverse_z`` / z (the
    train's speed along the camera's axis times the exposure time); the sky stays."""
    height, width = inverse_z.shape
    for r in range(height):
        for col in range(width):
            iz = inverse_z[r, col]
            du = (col + 0.5 - focus_u) * per_inverse_z * iz
            dv = (r + 0.5 - focus_v) * per_inverse_z * iz
            steps = int(min(math.sqrt(du * du + dv * dv) / 2.0, 8.0)) + 1
            if steps == 1:
                out[r, col, 0] = image[r, col, 0]
                out[r, col, 1] = image[r, col, 1]
                out[r, col, 2] = image[r, col, 2]
                continue
            sr = 0.0
            sg = 0.0
            sb = 0.0
            for s in range(steps):
                f = s / (steps - 1.0)
                sc = min(max(int(col - f * du), 0), width - 1)
                ss = min(max(int(r - f * dv), 0), height - 1)
                sr += image[ss, sc, 0]
                sg += image[ss, sc, 1]
                sb += image[ss, sc, 2]
            out[r, col, 0] = sr / steps
            out[r, col, 1] = sg / steps
            out[r, col, 2] = sb / steps


@_jit
def streaks(image, segments, colour):  # type: ignore[no-untyped-def]
    """Blend rain streaks into ``image``: ``segments`` rows (u0, v0, u1, v1, opacity), each
    drawn one pixel wide towards ``colour``."""
    height, width = image.shape[0], image.shape[1]
    for s in range(segments.shape[0]):
        u0, v0, u1, v1, alpha = (
            segments[s, 0],
            segments[s, 1],
            segments[s, 2],
            segments[s, 3],
            segments[s, 4],
        )
        n = int(max(abs(u1 - u0), abs(v1 - v0))) + 1
        for i in range(n):
            f = i / n
            c = int(u0 + f * (u1 - u0))
            r = int(v0 + f * (v1 - v0))
            if 0 <= r < height and 0 <= c < width:
                for ch in range(3):
                    image[r, c, ch] += alpha * (colour[ch] - image[r, c, ch])


@_jit
def flakes(image, discs, colour):  # type: ignore[no-untyped-def]
    """Blend snowflakes into ``image``: ``discs`` rows (u, v, radius, opacity)."""
    height, width = image.shape[0], image.shape[1]
    for s in range(discs.shape[0]):
        u, v, radius, alpha = discs[s, 0], discs[s, 1], discs[s, 2], discs[s, 3]
        r0 = max(int(v - radius), 0)
        r1 = min(int(v + radius) + 1, height)
        c0 = max(int(u - radius), 0)
        c1 = min(int(u + radius) + 1, width)
        for r in range(r0, r1):
            for c in range(c0, c1):
                du = c + 0.5 - u
                dv = r + 0.5 - v
                if du * du + dv * dv <= radius * radius:
                    for ch in range(3):
                        image[r, c, ch] += alpha * (colour[ch] - image[r, c, ch])


@_jit
def metered(image):  # type: ignore[no-untyped-def]
    """Mean luma (Rec. 601) of the lower two thirds of ``image``: what auto-exposure meters."""
    height, width = image.shape[0], image.shape[1]
    total = 0.0
    first = height // 3
    for r in range(first, height):
        for c in range(width):
            total += 0.299 * image[r, c, 0] + 0.587 * image[r, c, 1] + 0.114 * image[r, c, 2]
    return total / max((height - first) * width, 1)


@_jit
def _hash(key):  # type: ignore[no-untyped-def]
    """SplitMix64's finaliser: a well-mixed 64-bit word of ``key``."""
    z = (key + np.uint64(0x9E3779B97F4A7C15)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    z = ((z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    z = ((z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    return z ^ (z >> np.uint64(31))


DEVIATES = np.random.default_rng(20240601).standard_normal(65536)
"""A fixed table of standard normal deviates: the noise picks from it by hash."""


@_jit
def finish(  # type: ignore[no-untyped-def]
    image,
    scale,
    per_electron,
    electrons_per_unit,
    read_noise_e,
    key,
    table,
    out,
    row_begin,
    row_end,
):
    """``out`` (uint8) = ``image`` * ``scale`` with sensor noise when ``per_electron`` > 0:
    a pixel at value y collected y * ``electrons_per_unit`` photo-electrons; shot noise
    (their square root) and read noise (``read_noise_e``) in electrons, times
    ``per_electron`` (digital numbers per electron, the gain), the deviation looked up per
    quarter DN of the level. Each pixel's three normal
    deviates are picked from ``table`` (65536 of them) by 16-bit parts of a hash of ``key``
    and the pixel's index, so the noise is the same for the same key (and for a band of rows
    ``row_begin`` to ``row_end``, the rows this call finishes, as for the whole frame)."""
    width = image.shape[1]
    mix = np.uint64(key)
    read2 = read_noise_e * read_noise_e
    # the noise's standard deviation [DN] by level, every quarter DN up to full scale
    sigma = np.empty(1025)
    for i in range(1025):
        sigma[i] = per_electron * math.sqrt(i / 4.0 * electrons_per_unit + read2)
    for r in range(row_begin, row_end):
        for c in range(width):
            word = np.uint64(0)
            if per_electron > 0.0:
                index = np.uint64(r * width + c)
                word = _hash(mix ^ (index * np.uint64(0xD1B54A32D192ED03)))
            for ch in range(3):
                y = image[r, c, ch] * scale
                if per_electron > 0.0:
                    deviate = table[(word >> np.uint64(16 * ch)) & np.uint64(0xFFFF)]
                    level = min(max(int(y * 4.0 + 0.5), 0), 1024)
                    y += sigma[level] * deviate
                y += 0.5
                if y < 0.0:
                    y = 0.0
                elif y > 255.0:
                    y = 255.0
                out[r, c, ch] = np.uint8(y)


@_jit
def depth_words(ids, inverse_z, normals, codes, focal, max_distance, out):  # type: ignore[no-untyped-def]
    """A depth frame: per pixel class/id code, distance over ``max_distance`` and |cos| of
    the incidence, each scaled to 0..65535; all zero where nothing is within range."""
    height, width = ids.shape
    half_w = width / 2.0
    half_h = height / 2.0
    for r in range(height):
        yr = -(r + 0.5 - half_h) / focal
        for col in range(width):
            face = ids[r, col]
            if face == 0:
                out[r, col, 0] = 0
                out[r, col, 1] = 0
                out[r, col, 2] = 0
                continue
            xr = (col + 0.5 - half_w) / focal
            length = math.sqrt(xr * xr + yr * yr + 1.0)
            distance = length / inverse_z[r, col]
            if distance > max_distance:
                out[r, col, 0] = 0
                out[r, col, 1] = 0
                out[r, col, 2] = 0
                continue
            cosine = abs(normals[face, 0] * xr + normals[face, 1] * yr + normals[face, 2]) / length
            out[r, col, 0] = codes[face]
            out[r, col, 1] = np.uint16(round(min(distance / max_distance, 1.0) * 65535.0))
            out[r, col, 2] = np.uint16(round(min(cosine, 1.0) * 65535.0))
