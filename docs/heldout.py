#!/usr/bin/env python3
"""The held-out set the default tracker is chosen on (docs/robustness.md, "The default tracker,
chosen on held-out renders").

Textures are split in two halves, each with natural photographs, periodic textures (bricks,
tiles, stripes), text and sparse targets: the policy is tuned on `tune` and reported on
`heldout`, which nothing was tuned on. Each texture is rendered by `regtrack synth` under the
kinds of footage below (the UCSB and TMT motion profiles at 1x to 3x speed, blur, noise, JPEG,
light that changes across the target, partial occlusion):

    python3 docs/heldout.py render OUT           # OUT/tune/*.txt, OUT/heldout/*.txt (~1 min)
    python3 docs/heldout.py render-appearance OUT  # the same halves under strong changes of
                                                 # light (APPEARANCE_KINDS; for `pca`)
    python3 docs/heldout.py render-hue OUT       # the same halves in colour, the texture's
                                                 # pattern mostly in hue (HUE_KINDS; for
                                                 # `channels = rgb`)
    python3 docs/heldout.py render-bend OUT      # the same halves bending (BEND_KINDS: the
                                                 # texture waves, its corners with it; for
                                                 # the non-rigid SSMs, `spline` and `tps`)
    python3 docs/heldout.py eval OUT NAME [regtrack eval options...]
        # runs `regtrack eval` on both halves into OUT/runs/NAME/{tune,heldout}
    python3 docs/heldout.py table OUT NAME...    # SR@5 by kind and half, frame-weighted

The procedural textures (tiles, stripes, text, sparse marks, bricks) are drawn here from a
seed (CC0, like this script); the photographs are scikit-image's (see
assets/textures/SKIMAGE_IMAGE_SOURCES_AND_LICENSES.txt). Needs numpy and Pillow.
"""

import csv
import glob
import json
import os
import subprocess
import sys

import numpy as np
from PIL import Image, ImageDraw, ImageFont

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")
TEXTURE_DIRS = [
    os.path.join(ROOT, "assets", "textures"),
    os.path.join(ROOT, "..", "shared", "data", "textures"),
]
MOTION_DIRS = [
    os.path.join(ROOT, "assets", "motion"),
    os.path.join(ROOT, "..", "shared", "data", "motion"),
]
BIN = os.environ.get("REGTRACK_BIN", os.path.join(ROOT, "target", "release", "regtrack"))
SIDE = 512


def find(dirs, name):
    for d in dirs:
        p = os.path.join(d, name)
        if os.path.exists(p):
            return p
    sys.exit(f"{name}: not in {', '.join(dirs)}")


# --- procedural textures (SIDE x SIDE, 8-bit gray) ---------------------------------------


def tiles(rng, n, grout):
    """n x n tiles of random grays, grout lines between them, a little speckle."""
    cell = SIDE / n
    y, x = np.mgrid[0:SIDE, 0:SIDE]
    i, j = (x // cell).astype(int), (y // cell).astype(int)
    shade = rng.uniform(60, 200, size=(n + 1, n + 1))[j, i]
    fx, fy = (x % cell) / cell, (y % cell) / cell
    line = (np.minimum(fx, 1 - fx) < grout) | (np.minimum(fy, 1 - fy) < grout)
    img = np.where(line, 235.0, shade) + rng.normal(0, 6, size=(SIDE, SIDE))
    return img


def bricks(rng, rows, per_row):
    """Running-bond bricks: `rows` courses of `per_row` bricks, mortar between, each brick its
    own shade."""
    h, w = SIDE / rows, SIDE / per_row
    y, x = np.mgrid[0:SIDE, 0:SIDE]
    r = (y // h).astype(int)
    xs = x + (r % 2) * w / 2
    c = (xs // w).astype(int)
    shade = rng.uniform(70, 150, size=(rows + 1, per_row + 2))[r, c]
    fx, fy = (xs % w) / w, (y % h) / h
    mortar = (np.minimum(fx, 1 - fx) < 0.06) | (np.minimum(fy, 1 - fy) < 0.1)
    return np.where(mortar, 210.0, shade) + rng.normal(0, 10, size=(SIDE, SIDE))


def stripes(rng, period, angle):
    """Sinusoidal stripes at `angle` (radians) with a slow second pattern across them."""
    y, x = np.mgrid[0:SIDE, 0:SIDE]
    u = x * np.cos(angle) + y * np.sin(angle)
    v = -x * np.sin(angle) + y * np.cos(angle)
    img = 128 + 80 * np.sin(2 * np.pi * u / period) + 30 * np.sin(2 * np.pi * v / (SIDE / 1.7))
    return img + rng.normal(0, 5, size=(SIDE, SIDE))


def text(rng, size):
    """Lines of random words in a serif font, black on paper."""
    img = Image.new("L", (SIDE, SIDE), 235)
    draw = ImageDraw.Draw(img)
    try:
        font = ImageFont.truetype("DejaVuSerif.ttf", size)
    except OSError:
        font = ImageFont.load_default(size=size)
    letters = "abcdefghijklmnopqrstuvwxyz"
    y = 4
    while y < SIDE:
        words = [
            "".join(rng.choice(list(letters), size=rng.integers(2, 9))) for _ in range(12)
        ]
        draw.text((4 - rng.integers(0, 3 * size), y), " ".join(words), fill=20, font=font)
        y += int(size * 1.35)
    return np.asarray(img, dtype=np.float64) + rng.normal(0, 3, size=(SIDE, SIDE))


def sparse(rng, marks):
    """A few dark marks (discs, bars, rings) on a light, almost flat card."""
    img = Image.new("L", (SIDE, SIDE), 205)
    draw = ImageDraw.Draw(img)
    for _ in range(marks):
        x, y = rng.uniform(40, SIDE - 40, size=2)
        r = rng.uniform(12, 40)
        kind = rng.integers(0, 3)
        shade = int(rng.uniform(10, 90))
        if kind == 0:
            draw.ellipse((x - r, y - r, x + r, y + r), fill=shade)
        elif kind == 1:
            draw.rectangle((x - r, y - r / 4, x + r, y + r / 4), fill=shade)
        else:
            draw.ellipse((x - r, y - r, x + r, y + r), outline=shade, width=int(r / 3))
    y, x = np.mgrid[0:SIDE, 0:SIDE]
    shading = 10 * np.sin(x / SIDE * 3.0) * np.cos(y / SIDE * 2.0)
    return np.asarray(img, dtype=np.float64) + shading + rng.normal(0, 2, size=(SIDE, SIDE))


PROCEDURAL = {
    # tune half
    "tiles12": lambda r: tiles(r, 12, 0.07),
    "stripes14": lambda r: stripes(r, SIDE / 14, 0.35),
    "text_a": lambda r: text(r, 30),
    "sparse_a": lambda r: sparse(r, 7),
    # held-out half
    "tiles8": lambda r: tiles(r, 8, 0.05),
    "bricks16": lambda r: bricks(r, 16, 6),
    "text_b": lambda r: text(r, 22),
    "sparse_b": lambda r: sparse(r, 5),
}

# The halves: (texture, its class). Every class is in both.
HALVES = {
    "tune": [
        ("skimage_coffee.png", "natural"),
        ("skimage_camera.png", "natural"),
        ("tiles12", "periodic"),
        ("stripes14", "periodic"),
        ("text_a", "text"),
        ("sparse_a", "sparse"),
    ],
    "heldout": [
        ("skimage_astronaut.png", "natural"),
        ("skimage_chelsea.png", "natural"),
        ("skimage_brick.png", "periodic"),
        ("tiles8", "periodic"),
        ("bricks16", "periodic"),
        ("text_b", "text"),
        ("sparse_b", "sparse"),
    ],
}

# The kinds of footage: (kind, sequence suffix, motion profile, synth options). A kind marked
# with a class applies only to textures of that class.
KINDS = [
    ("fast", "m1x2", "ucsb_bricks_m1", ["--step", "2", "--noise", "2"]),
    ("fast", "m1x3b", "ucsb_bricks_m1", ["--step", "3", "--motion-blur", "3", "--noise", "2"]),
    ("fast", "m2", "ucsb_bricks_m2", ["--noise", "2", "--jpeg-quality", "80"]),
    ("fast", "m2x2", "ucsb_bricks_m2", ["--step", "2", "--noise", "2"]),
    ("fast", "m3b", "ucsb_bricks_m3", ["--motion-blur", "3", "--noise", "2"]),
    ("fast", "uc", "ucsb_bricks_uc", ["--noise", "2", "--occlusion", "0.1"]),
    ("panning_light", "pd", "ucsb_bricks_pd", ["--local-light", "0.4", "--gain-drift", "0.2"]),
    ("panning_light", "rt", "ucsb_bricks_rt", ["--bias-drift", "20", "--noise", "2"]),
    ("panning_light", "pdx2", "ucsb_bricks_pd", ["--step", "2", "--local-light", "0.3"]),
    ("slow", "m1", "ucsb_bricks_m1", ["--noise", "2"]),
    ("slow", "zm", "ucsb_bricks_zm", ["--noise", "3", "--jpeg-quality", "70"]),
    ("slow", "book", "tmt_dl_bookIII_s5", ["--noise", "2", "--occlusion", "0.15"]),
    ("static_light", "ld", "ucsb_bricks_ld", ["--local-light", "0.5", "--gain-drift", "0.3"]),
]
BACKGROUNDS = ["skimage_grass.png", "skimage_coffee.png"]

# The bending set (`render-bend`): the target bends as cloth or a page does (`synth --bend`,
# the amplitude a fraction of its size), on slow and faster profiles.
BEND_KINDS = [
    ("bend", "bm1", "ucsb_bricks_m1", ["--bend", "0.04", "--noise", "2"]),
    ("bend", "bbook", "tmt_dl_bookIII_s5", ["--bend", "0.06", "--noise", "2"]),
    ("bend", "bzm", "ucsb_bricks_zm", ["--bend", "0.05", "--noise", "2", "--jpeg-quality", "80"]),
    ("bend_fast", "bm2", "ucsb_bricks_m2", ["--bend", "0.05", "--noise", "2"]),
]

# The appearance set (`render-appearance`): the target's appearance changes much more than in
# KINDS, by light that sweeps across it and dims it (what a learnt appearance model, `pca`,
# is for); long, slow profiles.
APPEARANCE_KINDS = [
    ("light_sweep", "ls", "tmt_dl_bookIII_s5", ["--local-light", "0.9", "--gain-drift", "0.4", "--noise", "2"]),
    ("light_sweep", "lsu", "ucsb_bricks_uc", ["--local-light", "0.8", "--bias-drift", "30", "--noise", "2"]),
    ("dimming", "dm", "ucsb_bricks_ld", ["--local-light", "0.7", "--gain-drift", "0.6", "--noise", "2"]),
]


# The hue set (`render-hue`): every texture of the halves recoloured so that its pattern is
# mostly in hue (HUE_LUMA of its contrast left in luma, the rest along a red-green axis of
# constant luma), on a background whose pattern is along the blue-yellow axis: in grey both
# lose most of their contrast. Faster and slower profiles of KINDS.
HUE_KINDS = [k for k in KINDS if k[1] in ("m1x2", "m2", "m3b", "uc", "pd", "rt", "m1", "book")]
HUE_LUMA = 0.15
# BT.601 luma weights (as regtrack's grey) and two directions of constant luma.
LUMA = np.array([0.299, 0.587, 0.114])
RED_GREEN = np.array([0.587, -0.299, 0.0])
BLUE_YELLOW = np.cross(LUMA, RED_GREEN)


def recolour(grey, axis):
    """A grey texture (0..255) as colour: HUE_LUMA of its contrast in luma, the rest along
    `axis` (of constant luma), scaled to stay within 0..255 around mid-grey."""
    g = grey.astype(np.float64)
    d = (g - g.mean()) / max(g.std(), 1e-6)
    axis = axis / np.abs(axis).max()
    rgb = 128.0 + 40.0 * HUE_LUMA * d[..., None] + 70.0 * d[..., None] * axis
    return np.clip(rgb, 0, 255).astype(np.uint8)


def hue_textures(tex_dir):
    """The recoloured textures (target and background versions) in `tex_dir`; returns the
    path of a texture's or background's recoloured file."""
    def path(texture, axis_name):
        src = (
            os.path.join(tex_dir, texture + ".png")
            if texture in PROCEDURAL
            else find(TEXTURE_DIRS, texture)
        )
        base = os.path.basename(src).replace(".png", "")
        out = os.path.join(tex_dir, f"{base}_{axis_name}.png")
        if not os.path.exists(out):
            grey = np.asarray(Image.open(src).convert("L"))
            axis = RED_GREEN if axis_name == "rg" else BLUE_YELLOW
            Image.fromarray(recolour(grey, axis)).save(out)
        return out
    return path


def render(out, kinds_of_footage=KINDS, hue=False):
    tex_dir = os.path.join(out, "textures")
    os.makedirs(tex_dir, exist_ok=True)
    for k, (name, make) in enumerate(PROCEDURAL.items()):
        path = os.path.join(tex_dir, name + ".png")
        if not os.path.exists(path):
            img = make(np.random.default_rng(1000 + k))
            Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(path)
    coloured = hue_textures(tex_dir)
    kinds = {}
    for half, textures in HALVES.items():
        root = os.path.join(out, half)
        os.makedirs(root, exist_ok=True)
        for t, (texture, cls) in enumerate(textures):
            tex = (
                os.path.join(tex_dir, texture + ".png")
                if texture in PROCEDURAL
                else find(TEXTURE_DIRS, texture)
            )
            base = texture.replace("skimage_", "").replace(".png", "")
            for k, (kind, suffix, motion, opts) in enumerate(kinds_of_footage):
                name = f"{base}_{suffix}"
                # A periodic texture on grass moving 5 px a frame is its own kind too.
                kinds[f"{half}/{name}"] = (kind, cls)
                bg = BACKGROUNDS[(t + k) % 2] if texture != "skimage_coffee.png" else BACKGROUNDS[0]
                if texture == "skimage_grass.png":
                    bg = BACKGROUNDS[1]
                if os.path.exists(os.path.join(root, name + ".txt")):
                    continue
                bg_path = find(TEXTURE_DIRS, bg)
                if hue:
                    tex, bg_path = coloured(texture, "rg"), coloured(bg, "by")
                cmd = [
                    BIN, "synth", "--texture", tex, "--background", bg_path,
                    "--motion", find(MOTION_DIRS, motion + ".txt"), "--out", root,
                    "--name", name, "--seed", str(7 + 13 * t + k),
                ] + opts
                subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    with open(os.path.join(out, "kinds.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sequence", "kind", "class"])
        for seq, (kind, cls) in sorted(kinds.items()):
            w.writerow([seq, kind, cls])


def evaluate(out, name, args):
    # HALVES=tune evaluates one half only (while tuning).
    for half in os.environ.get("HALVES", ",".join(HALVES)).split(","):
        cmd = [
            BIN, "eval", "--dataset", os.path.join(out, half),
            "--out", os.path.join(out, "runs", name, half), "--jobs", "2",
        ] + args
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def kind_of(out):
    with open(os.path.join(out, "kinds.csv")) as f:
        rows = list(csv.DictReader(f))
    kinds = {r["sequence"]: r["kind"] for r in rows}
    # The small periodic textures at 5 px a frame: a kind of their own, as the issue measured.
    for r in rows:
        if r["class"] == "periodic" and r["sequence"].endswith("_m1"):
            kinds[r["sequence"]] = "periodic_5px"
    return kinds


def rows(out, names):
    """(run name, half, tracker, sequence, frames, frames within 5 px, lost>20, lost<5)."""
    for name in names:
        for half in HALVES:
            path = os.path.join(out, "runs", name, half, "summary.csv")
            if not os.path.exists(path):
                continue
            with open(path) as f:
                for r in csv.DictReader(f):
                    # The pooled rows (`ALL`, `ALL:<factor>`) repeat the sequences' frames.
                    if r["sequence"] == "ALL" or r["sequence"].startswith("ALL:"):
                        continue
                    frames = int(r["frames"])
                    yield (name, half, r["tracker"], f"{half}/{r['sequence']}", frames,
                           float(r["sr5"]) * frames, r["lost_when_off"], r["lost_when_on"])


def loss_counts(out, name, half, tracker):
    """Pooled loss detection of a tracker over a half: frames searched more than 20 px off and
    those of them reported lost, frames within 5 px and those reported lost (as `regtrack
    eval`'s lost>20 and lost<5, over every sequence)."""
    off = off_lost = on = on_lost = 0
    pattern = os.path.join(out, "runs", name, half, "tracking_data", "*", tracker + "_run.json")
    for path in glob.glob(pattern):
        with open(path) as f:
            frames = json.load(f)["frames"]
        for fr in frames:
            e = fr.get("estimate_error")
            if fr.get("init") or not fr.get("searched") or fr.get("ground_truth") is None:
                continue
            lost = fr["status"]["status"] != "tracking"
            e = float("inf") if e is None else e
            if e > 20:
                off, off_lost = off + 1, off_lost + lost
            elif e <= 5:
                on, on_lost = on + 1, on_lost + lost
    return off, off_lost, on, on_lost


def table(out, names):
    kinds = kind_of(out)
    order = ["fast", "periodic_5px", "panning_light", "slow", "static_light", "all"]
    if any(k in ("light_sweep", "dimming") for k in kinds.values()):
        order = ["light_sweep", "dimming", "all"]
    if any(k in ("bend", "bend_fast") for k in kinds.values()):
        order = ["bend", "bend_fast", "all"]
    acc = {}
    for name, half, tracker, seq, frames, within, _, _ in rows(out, names):
        for kind in (kinds.get(seq, "?"), "all"):
            key = (half, f"{name}:{tracker}", kind)
            n, w = acc.get(key, (0, 0.0))
            acc[key] = (n + frames, w + within)
    for half in HALVES:
        trackers = sorted({k[1] for k in acc if k[0] == half})
        print(f"\n{half}: SR@5, frame-weighted")
        print("| tracker | " + " | ".join(order) + " | lost>20 | lost<5 |")
        print("|---|" + "---|" * (len(order) + 2))
        for t in trackers:
            cells = []
            for kind in order:
                n, w = acc.get((half, t, kind), (0, 0.0))
                cells.append(f"{w / n:.3f}" if n else "-")
            name, tracker = t.split(":", 1)
            off, off_lost, on, on_lost = loss_counts(out, name, half, tracker)
            cells.append(f"{off_lost}/{off}")
            cells.append(f"{on_lost}/{on} ({on_lost / max(on, 1):.3f})")
            print(f"| {t} | " + " | ".join(cells) + " |")


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    cmd, out = sys.argv[1], sys.argv[2]
    if cmd == "render":
        render(out)
    elif cmd == "render-appearance":
        render(out, APPEARANCE_KINDS)
    elif cmd == "render-hue":
        render(out, HUE_KINDS, hue=True)
    elif cmd == "render-bend":
        render(out, BEND_KINDS)
    elif cmd == "eval":
        evaluate(out, sys.argv[3], sys.argv[4:])
    elif cmd == "table":
        table(out, sys.argv[3:] or sorted(os.listdir(os.path.join(out, "runs"))))
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
