"""Draws docs/watertight.png: one sphere extracted at tolerance 0 (marching cubes) and at a
tolerance where hierarchy nodes are emitted whole as fans, wireframes side by side.

Usage: /usr/bin/python3 scripts/figure_watertight.py [build/isoserve]
Needs Debian's python3-matplotlib and python3-numpy (not part of the test set-up)."""

import os
import subprocess
import sys
import tempfile

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

BIN = sys.argv[1] if len(sys.argv) > 1 else "build/isoserve"
FIELD, LEVEL = "field:sphere:40", 4


def read_ply(path):
    data = open(path, "rb").read()
    head, _, body = data.partition(b"end_header\n")
    words = head.split()
    nv = int(words[words.index(b"vertex") + 1])
    nt = int(words[words.index(b"face") + 1])
    pos = np.frombuffer(body[: 12 * nv], "<f4").reshape(nv, 3)
    faces = np.frombuffer(body[12 * nv : 12 * nv + 13 * nt], dtype=np.dtype([("n", "u1"), ("i", "<u4", 3)]))
    return pos, faces["i"]


def extract(tolerance, tmp):
    out = os.path.join(tmp, f"t{tolerance}.ply")
    subprocess.run([BIN, "extract", FIELD, "--level", str(LEVEL), "--tolerance", str(tolerance),
                    "--normals", "none", "--index-space", "-o", out], check=True, stdout=subprocess.DEVNULL)
    return read_ply(out)


def panel(ax, pos, tri, title, limits):
    # The octant facing the viewer, so the triangles are not hidden behind each other.
    centre = pos.mean(axis=0)
    keep = np.all(pos[tri].mean(axis=1) >= centre - 1, axis=1)
    corners = pos[tri[keep]]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    colours = plt.cm.viridis(np.clip(area / 1.5, 0, 1))
    ax.add_collection3d(Poly3DCollection(corners, facecolors=colours, edgecolors="k", linewidths=0.2))
    lo, hi = limits
    ax.set_xlim(lo[0], hi[0]), ax.set_ylim(lo[1], hi[1]), ax.set_zlim(lo[2], hi[2])
    ax.view_init(elev=25, azim=40)
    ax.set_axis_off()
    ax.set_title(f"{title}\n{len(tri)} triangles in all", fontsize=9)


def main():
    with tempfile.TemporaryDirectory() as tmp:
        exact = extract(0, tmp)
        coarse = extract(0.5, tmp)
    centre = exact[0].mean(axis=0)
    limits = (centre - 1, exact[0].max(axis=0))
    fig = plt.figure(figsize=(9, 4.8), dpi=110)
    panel(fig.add_subplot(1, 2, 1, projection="3d"), *exact, "tolerance 0: marching cubes", limits)
    panel(fig.add_subplot(1, 2, 2, projection="3d"), *coarse,
          "tolerance 0.5: fans (light) beside cells (dark)", limits)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.86)
    fig.savefig("docs/watertight.png")
    print("wrote docs/watertight.png")


if __name__ == "__main__":
    main()
