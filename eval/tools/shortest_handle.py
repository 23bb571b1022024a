#!/usr/bin/env python3
"""Shortest non-separating cycle of closed triangle meshes.

For each mesh (OBJ or OFF) prints the vertex count, the genus (from V - E + F
of a closed, connected mesh) and, when the genus is positive, the length of
the shortest non-separating (homologically non-trivial) edge cycle divided by
sqrt(surface area): how thin the thinnest handle is. Measures whether a bound
on that length could tell handles made by fused contacts (SHREC'11 simplified)
from real ones (SHREC'07 cups, vases, glasses); docs/results.md gives the
figures.

Method: a tree-cotree decomposition (Eppstein 2003) gives 2g leftover edges;
the dual cycle of each is a cocycle, and a cycle is non-trivial in Z/2
homology iff it crosses some cocycle an odd number of times (one bit per
cocycle, XORed along the cycle). The shortest non-trivial cycle is the
fundamental cycle of a non-tree edge in the shortest-path tree of one of its
own vertices (Erickson and Har-Peled 2004), so trying every root is exact;
--roots N tries every (V / N)-th vertex only: an upper bound, for large
meshes. Pure Python (no NumPy on the build machines), O(V^2 log V) exact.

  eval/tools/shortest_handle.py [--roots N] MESH...
"""
import argparse
import heapq
import math
import sys
from collections import defaultdict, deque


def load(path):
    """Returns (vertices, triangles) of an OBJ or OFF file (polygons fanned)."""
    verts, faces = [], []

    def fan(poly):
        for k in range(1, len(poly) - 1):
            faces.append((poly[0], poly[k], poly[k + 1]))

    if path.lower().endswith('.off'):
        tokens = []
        for line in open(path, errors='replace'):
            line = line.split('#')[0]
            tokens.extend(line.split())
        if tokens[0].upper() == 'OFF':
            tokens = tokens[1:]
        nv, nf = int(tokens[0]), int(tokens[1])
        pos = 3
        for _ in range(nv):
            verts.append(tuple(float(t) for t in tokens[pos:pos + 3]))
            pos += 3
        for _ in range(nf):
            k = int(tokens[pos])
            fan([int(t) for t in tokens[pos + 1:pos + 1 + k]])
            pos += 1 + k
    else:
        for line in open(path, errors='replace'):
            p = line.split()
            if not p:
                continue
            if p[0] == 'v':
                verts.append(tuple(float(t) for t in p[1:4]))
            elif p[0] == 'f':
                fan([int(t.split('/')[0]) - 1 for t in p[1:]])
    return verts, faces


def dist(a, b):
    return math.sqrt(sum((a[i] - b[i]) ** 2 for i in range(3)))


def tri_area(a, b, c):
    u = [b[i] - a[i] for i in range(3)]
    v = [c[i] - a[i] for i in range(3)]
    w = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
         u[0] * v[1] - u[1] * v[0])
    return 0.5 * math.sqrt(sum(x * x for x in w))


def analyze(path, roots):
    verts, faces = load(path)
    index, edge_faces, edges = {}, defaultdict(list), []
    for fi, (a, b, c) in enumerate(faces):
        for u, w in ((a, b), (b, c), (c, a)):
            key = (min(u, w), max(u, w))
            if key not in index:
                index[key] = len(edges)
                edges.append(key)
            edge_faces[index[key]].append(fi)
    used = sorted({v for f in faces for v in f})
    n = len(used)
    genus = (2 - (n - len(edges) + len(faces))) // 2
    area = sum(tri_area(verts[a], verts[b], verts[c]) for a, b, c in faces)
    if genus <= 0:
        return n, genus, None
    adj = defaultdict(list)
    for i, (u, w) in enumerate(edges):
        length = dist(verts[u], verts[w])
        adj[u].append((w, i, length))
        adj[w].append((u, i, length))
    # Tree (BFS over vertices), cotree (BFS over faces across non-tree edges).
    tree, seen, queue = set(), {used[0]}, deque([used[0]])
    while queue:
        v = queue.popleft()
        for w, i, _ in adj[v]:
            if w not in seen:
                seen.add(w)
                tree.add(i)
                queue.append(w)
    face_adj = defaultdict(list)
    for i in range(len(edges)):
        if i not in tree and len(edge_faces[i]) == 2:
            f, g = edge_faces[i]
            face_adj[f].append((g, i))
            face_adj[g].append((f, i))
    face_parent, cotree, queue = {0: (-1, -1)}, set(), deque([0])
    while queue:
        f = queue.popleft()
        for g, i in face_adj[f]:
            if g not in face_parent:
                face_parent[g] = (f, i)
                cotree.add(i)
                queue.append(g)
    leftover = [i for i in range(len(edges)) if i not in tree and i not in cotree]

    def to_root(f):
        out = set()
        while face_parent[f][0] >= 0:
            out.add(face_parent[f][1])
            f = face_parent[f][0]
        return out

    # Bit j of mask[e]: edge e lies on the dual cycle of leftover edge j.
    mask = [0] * len(edges)
    for j, e in enumerate(leftover):
        f, g = edge_faces[e]
        for i in (to_root(f) ^ to_root(g)) | {e}:
            mask[i] ^= 1 << j
    best = math.inf
    step = 1 if roots <= 0 else max(1, n // roots)
    for r in used[::step]:
        d = {r: 0.0}
        parent_edge, path_mask, heap, order = {}, {r: 0}, [(0.0, r)], []
        done = set()
        while heap:
            dv, v = heapq.heappop(heap)
            if v in done:
                continue
            done.add(v)
            order.append(v)
            if v != r:
                i = parent_edge[v]
                u = edges[i][0] if edges[i][1] == v else edges[i][1]
                path_mask[v] = path_mask[u] ^ mask[i]
            for w, i, length in adj[v]:
                if dv + length < d.get(w, math.inf):
                    d[w] = dv + length
                    parent_edge[w] = i
                    heapq.heappush(heap, (d[w], w))
        tree_edges = set(parent_edge.values())
        for i, (u, w) in enumerate(edges):
            if i in tree_edges or not (path_mask[u] ^ path_mask[w] ^ mask[i]):
                continue
            best = min(best, d[u] + d[w] + dist(verts[u], verts[w]))
    return n, genus, best / math.sqrt(area)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--roots', type=int, default=0,
                        help='try about N roots (0: every vertex, exact)')
    parser.add_argument('meshes', nargs='+')
    args = parser.parse_args()
    print('mesh\tvertices\tgenus\tshortest_nontrivial_cycle/sqrt(area)')
    for path in args.meshes:
        n, genus, rel = analyze(path, args.roots)
        shown = '-' if rel is None else '%.4f' % rel
        print('%s\t%d\t%d\t%s' % (path, n, genus, shown))
        sys.stdout.flush()


if __name__ == '__main__':
    main()
