#!/usr/bin/env python3
"""Renders footage of the kind issue 17 calls "real": a hand-held camera moving around a box
with two textured planar faces, in perspective, lit by a lamp on the camera's rig, so that
one face turns to the light and brightens while the other turns away, shrinks and darkens.

Each face is a sequence in the MTF layout (the same frames, its own ground truth):
    python3 docs/render_box.py OUT [--frames 200] [--seed 1]
        -> OUT/box_left.txt, OUT/box_right.txt, OUT/box_left/frame00001.jpg ... (box_right/ links
           to box_left/)

Shading is Lambertian with the lamp's distance fall-off, per pixel, so the light varies across a
face as well as from frame to frame; the camera shakes smoothly (a few tenths of a degree),
sensor noise of sigma 2, JPEG at quality 85. Needs numpy and Pillow.
"""

import argparse
import math
import os
import sys

import numpy as np
from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
TEXTURES = os.path.join(HERE, "..", "assets", "textures")
# More CC0 textures, where the project's shared data is beside it.
SHARED_TEXTURES = os.path.join(HERE, "..", "..", "shared", "data", "textures")


def texture_path(name):
    for d in (TEXTURES, SHARED_TEXTURES):
        if os.path.exists(os.path.join(d, name)):
            return os.path.join(d, name)
    sys.exit(f"no texture {name} in {TEXTURES} or {SHARED_TEXTURES}")


def load_texture(name, side):
    img = Image.open(texture_path(name)).convert("L")
    w, h = img.size
    s = min(w, h)
    img = img.crop(((w - s) // 2, (h - s) // 2, (w - s) // 2 + s, (h - s) // 2 + s))
    return np.asarray(img.resize((side, side), Image.LANCZOS), dtype=np.float64)


def bilinear(tex, u, v):
    """Samples `tex` at texture coordinates u, v in [0, 1] (arrays)."""
    h, w = tex.shape
    x = np.clip(u * (w - 1), 0, w - 1.001)
    y = np.clip(v * (h - 1), 0, h - 1.001)
    x0 = np.floor(x).astype(int)
    y0 = np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    a = tex[y0, x0] * (1 - fx) + tex[y0, x0 + 1] * fx
    b = tex[y0 + 1, x0] * (1 - fx) + tex[y0 + 1, x0 + 1] * fx
    return a * (1 - fy) + b * fy


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--name", default="box")
    ap.add_argument("--textures", default="skimage_coffee.png,skimage_brick.png")
    ap.add_argument("--ss", type=int, default=2, help="supersampling per axis")
    ap.add_argument("--flat", action="store_true", help="constant light (no shading)")
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    W, H, f = 640, 480, 560.0
    side = 0.2  # a face is 20 cm wide and high
    tex_names = a.textures.split(",")
    texs = [load_texture(t, 512) for t in tex_names]
    background = np.asarray(
        Image.open(texture_path("skimage_grass.png")).convert("L").resize((W, H)),
        dtype=np.float64,
    ) * 0.5 + 30
    # The box's two faces meet at the vertical edge x = z = 0 (world), facing -z and +x... rotated
    # 45 degrees so that both face the camera at the start: each face as (origin, u axis, v axis).
    e1 = np.array([-side / math.sqrt(2), 0, -side / math.sqrt(2)])  # left face, along u
    e2 = np.array([side / math.sqrt(2), 0, -side / math.sqrt(2)])  # right face, along u
    down = np.array([0, side, 0])
    top = np.array([0, -side / 2, 0])
    faces = [
        (top + e1, -e1, down),  # left face: from its far edge to the shared edge
        (top, e2, down),  # right face: from the shared edge to its far edge
    ]
    lamp = np.array([0.5, -0.3, 0.0])  # on the camera's rig, to the right and above
    # Smooth hand-held shake: a few random sinusoids per axis.
    shake = [(rng.uniform(0.002, 0.005), rng.uniform(0.02, 0.08), rng.uniform(0, 6.3)) for _ in range(6)]
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    offs = [(i + 0.5) / a.ss - 0.5 for i in range(a.ss)]
    # The frames are the left face's folder; the right face's is a link to it.
    seq_dir = os.path.join(a.out, f"{a.name}_left")
    os.makedirs(seq_dir, exist_ok=True)
    link = os.path.join(a.out, f"{a.name}_right")
    if not os.path.lexists(link):
        os.symlink(f"{a.name}_left", link)
    gts = [[], []]
    shades = []
    for k in range(a.frames):
        t = k / max(1, a.frames - 1)
        # The camera orbits the box (yaw from -5 to +25 degrees) and backs away (0.9 to 1.4 m).
        yaw = math.radians(-5 + 30 * t)
        dist = 0.9 + 0.5 * t
        jx = sum(amp * math.sin(fr * k + ph) for amp, fr, ph in shake[:2])
        jy = sum(amp * math.sin(fr * k + ph) for amp, fr, ph in shake[2:4])
        jz = sum(amp * math.sin(fr * k + ph) for amp, fr, ph in shake[4:])
        # World to camera: rotate the world by -yaw about the box's edge, then push it away.
        R = rot_z(jz) @ rot_x(jx + 0.15) @ rot_y(jy) @ rot_y(-yaw)
        T = np.array([0.06 * math.sin(3 * math.pi * t), 0.02 + 0.03 * math.sin(2 * math.pi * t), dist])
        acc = np.zeros((H, W))
        shades.append([])
        for ox in offs:
            for oy in offs:
                img = background.copy()
                # Rays through the pixel in camera coordinates.
                dx = (xs + ox - W / 2) / f
                dy = (ys + oy - H / 2) / f
                for (o, u, v), tex in zip(faces, texs):
                    oc = R @ o + T
                    uc = R @ u
                    vc = R @ v
                    n = np.cross(uc, vc)
                    if np.dot(n, oc) >= 0:  # back-facing
                        n = -n
                    if np.dot(n, -oc) <= 0:
                        continue
                    # Solve s*d = oc + a*uc + b*vc for the ray d = (dx, dy, 1): a linear 3x3 per pixel.
                    M = np.stack([uc, vc], axis=1)
                    # Cramer's rule on [d, -uc, -vc] [s, a, b]^T = oc.
                    d0 = np.stack([dx, dy, np.ones_like(dx)], axis=-1)
                    A = np.empty((H, W, 3, 3))
                    A[..., :, 0] = d0
                    A[..., :, 1] = -M[:, 0]
                    A[..., :, 2] = -M[:, 1]
                    sol = np.linalg.solve(A, np.broadcast_to(oc, (H, W, 3))[..., None])[..., 0]
                    s_, a_, b_ = sol[..., 0], sol[..., 1], sol[..., 2]
                    inside = (a_ >= 0) & (a_ <= 1) & (b_ >= 0) & (b_ <= 1) & (s_ > 0)
                    if not inside.any():
                        continue
                    val = bilinear(tex, a_[inside], b_[inside])
                    # The lamp moves with the camera (a lamp on the rig).
                    lc = lamp
                    p = oc[None, :] + a_[inside, None] * uc[None, :] + b_[inside, None] * vc[None, :]
                    to_l = lc[None, :] - p
                    dl = np.linalg.norm(to_l, axis=1)
                    nn = n / np.linalg.norm(n)
                    lam = np.clip((to_l @ nn) / dl, 0, 1)
                    shade = 0.3 + 0.9 * lam / dl**2
                    if a.flat:
                        shade = np.full_like(shade, 0.8)
                    img[inside] = val * shade
                    shades[len(shades) - 1].append(float(shade.mean()))
                acc += img
        img = acc / (a.ss * a.ss)
        img += rng.normal(0, 2.0, img.shape)
        out = Image.fromarray(np.clip(np.round(img), 0, 255).astype(np.uint8))
        name = f"frame{k + 1:05d}.jpg"
        out.save(os.path.join(seq_dir, name), quality=85)
        for i, (o, u, v) in enumerate(faces):
            pts = []
            for c in (o, o + u, o + u + v, o + v):
                pc = R @ c + T
                pts += [W / 2 + f * pc[0] / pc[2] - 0.5, H / 2 + f * pc[1] / pc[2] - 0.5]
            gts[i].append((name, pts))
        if k % 20 == 0:
            sh = shades[-1]
            print(f"frame {k + 1}/{a.frames}: mean shade per face {sh[0]:.2f} {sh[-1]:.2f}", file=sys.stderr)
    for i, which in enumerate(("left", "right")):
        with open(os.path.join(a.out, f"{a.name}_{which}.txt"), "w") as fh:
            fh.write("frame\tulx\tuly\turx\tury\tlrx\tlry\tllx\tlly\n")
            for name, pts in gts[i]:
                fh.write(f"{name}\t" + "\t".join(f"{p:.3f}" for p in pts) + "\n")


if __name__ == "__main__":
    main()
