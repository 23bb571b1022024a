#!/usr/bin/env python3
"""Writes the intake test corpus (tests/data/meshes/{good,bad}).

Every file is small and synthetic; mesh_io_test.cc states what each one must
load as or fail with. Re-run after editing: python3 make_meshes.py
"""
import math
import os
import random
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
GOOD = os.path.join(HERE, "good")
BAD = os.path.join(HERE, "bad")

TETRA_V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
TETRA_F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]  # outward
CUBE_V = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
# Quads, counter-clockwise seen from outside.
CUBE_Q = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3),
          (0, 4, 6, 2), (1, 3, 7, 5)]


def cube_tris():
    out = []
    for a, b, c, d in CUBE_Q:
        out += [(a, b, c), (a, c, d)]
    return out


def write(path, data):
    mode = "wb" if isinstance(data, bytes) else "w"
    with open(path, mode) as f:
        f.write(data)


def off(vs, fs, header="OFF"):
    s = f"{header}\n{len(vs)} {len(fs)} 0\n"
    s += "".join(" ".join(repr(float(c)) for c in v) + "\n" for v in vs)
    s += "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in fs)
    return s


def obj(vs, fs):
    s = "# written by make_meshes.py\n"
    s += "".join("v " + " ".join(repr(float(c)) for c in v) + "\n" for v in vs)
    s += "".join("f " + " ".join(str(i + 1) for i in f) + "\n" for f in fs)
    return s


def ply_ascii(vs, fs):
    s = ("ply\nformat ascii 1.0\ncomment written by make_meshes.py\n"
         f"element vertex {len(vs)}\nproperty float x\nproperty float y\n"
         f"property float z\nelement face {len(fs)}\n"
         "property list uchar int vertex_indices\nend_header\n")
    s += "".join(" ".join(repr(float(c)) for c in v) + "\n" for v in vs)
    s += "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in fs)
    return s


def ply_binary(vs, fs, big, declared_vertices=None):
    e = ">" if big else "<"
    name = "binary_big_endian" if big else "binary_little_endian"
    nv = len(vs) if declared_vertices is None else declared_vertices
    head = (f"ply\nformat {name} 1.0\nelement vertex {nv}\n"
            "property double x\nproperty double y\nproperty double z\n"
            "property uchar red\n"
            f"element face {len(fs)}\nproperty list uchar int vertex_indices\n"
            "end_header\n").encode()
    body = b"".join(struct.pack(e + "dddB", *v, 200) for v in vs)
    body += b"".join(struct.pack(e + "B" + "i" * len(f), len(f), *f) for f in fs)
    return head + body


def normal(a, b, c):
    u = [b[i] - a[i] for i in range(3)]
    w = [c[i] - a[i] for i in range(3)]
    n = (u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
         u[0] * w[1] - u[1] * w[0])
    length = math.sqrt(sum(x * x for x in n)) or 1.0
    return tuple(x / length for x in n)


def stl_ascii(vs, fs):
    s = "solid tetra\n"
    for f in fs:
        a, b, c = (vs[i] for i in f)
        s += "  facet normal %g %g %g\n    outer loop\n" % normal(a, b, c)
        for p in (a, b, c):
            s += "      vertex %r %r %r\n" % tuple(float(x) for x in p)
        s += "    endloop\n  endfacet\n"
    return s + "endsolid tetra\n"


def stl_binary(vs, fs, declared=None):
    head = b"solid binary header that starts like ASCII".ljust(80, b" ")
    n = len(fs) if declared is None else declared
    body = b"".join(struct.pack("<12fH", *normal(*(vs[i] for i in f)),
                                *vs[f[0]], *vs[f[1]], *vs[f[2]], 0) for f in fs)
    return head + struct.pack("<I", n) + body


def hex_prism():
    # Regular hexagon of side 1 at z = 0 and z = 1; quads around, hexagon caps.
    ring = [(math.cos(k * math.pi / 3), math.sin(k * math.pi / 3)) for k in range(6)]
    vs = [(x, y, 0.0) for x, y in ring] + [(x, y, 1.0) for x, y in ring]
    fs = [tuple(range(5, -1, -1)), tuple(range(6, 12))]
    for k in range(6):
        j = (k + 1) % 6
        fs.append((k, j, 6 + j, 6 + k))
    return vs, fs


def main():
    os.makedirs(GOOD, exist_ok=True)
    os.makedirs(BAD, exist_ok=True)
    cube_t = cube_tris()

    # ---- good ----
    write(os.path.join(GOOD, "tetrahedron.off"),
          "# a comment line\n" + off(TETRA_V, TETRA_F))
    write(os.path.join(GOOD, "cube_quads.obj"), obj(CUBE_V, CUBE_Q))
    hv, hf = hex_prism()
    write(os.path.join(GOOD, "hex_prism_ngons.obj"), obj(hv, hf))
    write(os.path.join(GOOD, "cube_ascii.ply"), ply_ascii(CUBE_V, CUBE_Q))
    write(os.path.join(GOOD, "cube_binary_le.ply"), ply_binary(CUBE_V, cube_t, False))
    write(os.path.join(GOOD, "cube_binary_be.ply"), ply_binary(CUBE_V, CUBE_Q, True))
    write(os.path.join(GOOD, "tetrahedron_ascii.stl"), stl_ascii(TETRA_V, TETRA_F))
    write(os.path.join(GOOD, "cube_binary.stl"), stl_binary(CUBE_V, cube_t))
    # 2x2 grid of unit squares in the z = 0 plane: a disk with 8 boundary edges.
    grid_v = [(x, y, 0) for y in range(3) for x in range(3)]
    grid_f = []
    for y in range(2):
        for x in range(2):
            a = 3 * y + x
            grid_f += [(a, a + 1, a + 4), (a, a + 4, a + 3)]
    write(os.path.join(GOOD, "grid_with_boundary.off"), off(grid_v, grid_f))
    # Two disjoint tetrahedra (second shifted by 5 in x).
    two_v = TETRA_V + [(x + 5, y, z) for x, y, z in TETRA_V]
    two_f = TETRA_F + [tuple(i + 4 for i in f) for f in TETRA_F]
    write(os.path.join(GOOD, "two_tetrahedra.obj"), obj(two_v, two_f))
    # Tetrahedron + one duplicate face (reversed), one zero-area face through
    # an extra midpoint vertex, one face with a repeated vertex, and an
    # unused vertex.
    dv = TETRA_V + [(0.5, 0, 0), (9, 9, 9)]
    df = TETRA_F + [(1, 2, 0), (0, 4, 1), (0, 0, 3)]
    write(os.path.join(GOOD, "tetra_degenerate_duplicate.off"), off(dv, df))
    # Tetrahedron with one face wound the wrong way.
    write(os.path.join(GOOD, "tetra_one_flipped.off"),
          off(TETRA_V, TETRA_F[:3] + [(1, 3, 2)]))

    # ---- bad ----
    tetra = off(TETRA_V, TETRA_F).splitlines(keepends=True)
    write(os.path.join(BAD, "truncated.off"), "".join(tetra[:-2]))
    write(os.path.join(BAD, "wrong_counts.off"),
          "".join([tetra[0], "5 4 0\n"] + tetra[2:]))
    nan_lines = list(tetra)
    nan_lines[4] = "nan 1.0 0.0\n"
    write(os.path.join(BAD, "nan.off"), "".join(nan_lines))
    write(os.path.join(BAD, "index_out_of_range.obj"),
          obj(TETRA_V, TETRA_F[:3]) + "f 2 3 9\n")
    # Three triangles on edge (0, 1): intake repairs it (three sheets).
    write(os.path.join(GOOD, "nonmanifold_edge.off"),
          off([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1)],
              [(0, 1, 2), (1, 0, 3), (0, 1, 4)]))
    # Two cones (closed tetrahedra) touching at their tip, vertex 0: intake
    # repairs it (vertex 0 split in two).
    cone2 = [(0, 0, 0), (-1, 0, 0), (0, -1, 0), (0, 0, -1)]
    write(os.path.join(GOOD, "nonmanifold_vertex.off"),
          off(TETRA_V + cone2[1:],
              TETRA_F + [(0, 5, 4), (0, 4, 6), (0, 6, 5), (4, 5, 6)]))
    write(os.path.join(BAD, "empty.off"), "")
    write(os.path.join(BAD, "no_faces.off"), "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n")
    write(os.path.join(BAD, "face_two_vertices.off"),
          "".join(tetra[:-1]) + "2 1 2\n")
    rng = random.Random(20070601)
    garbage = bytes(rng.randrange(256) for _ in range(997))
    for ext in ("off", "obj", "ply", "stl"):
        write(os.path.join(BAD, f"garbage.{ext}"), garbage)
    write(os.path.join(BAD, "huge_count_binary.ply"),
          ply_binary(CUBE_V, cube_t, False, declared_vertices=10**12))
    write(os.path.join(BAD, "huge_count.stl"),
          stl_binary(TETRA_V, TETRA_F, declared=0xFFFFFFFF))
    write(os.path.join(BAD, "huge_count.off"), "OFF\n1000000000000 1 0\n0 0 0\n")
    full = ply_binary(CUBE_V, cube_t, False)
    write(os.path.join(BAD, "truncated_binary.ply"), full[:len(full) - 30])
    write(os.path.join(BAD, "truncated_ascii.stl"),
          "".join(stl_ascii(TETRA_V, TETRA_F).splitlines(keepends=True)[:12]))
    write(os.path.join(BAD, "nan_binary.stl"),
          stl_binary([(0, 0, 0), (1, 0, 0), (0, float("nan"), 0), (0, 0, 1)],
                     TETRA_F))


if __name__ == "__main__":
    main()
