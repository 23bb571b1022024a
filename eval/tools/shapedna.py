#!/usr/bin/python3
"""ShapeDNA reference retrieval, independent of the project's C++ code.

For every mesh of a manifest ('<relative path> <class>' per line, OFF or OBJ)
computes the first N non-zero Laplace-Beltrami eigenvalues with linear finite
elements (cotangent stiffness, consistent mass), multiplies them by the
surface area (scale invariance), compares two meshes by the L2 distance of
their eigenvalues weighted by 1/i, and prints leave-one-out NN / FT / ST /
DCG (Princeton Shape Benchmark definitions, the DCG of the SHREC'11 code).
This is the ShapeDNA that ../shared/data/README.md's reference scores use.

  /usr/bin/python3 eval/tools/shapedna.py MANIFEST [--eigenvalues 50]
      [--spectra OUT.txt] [--compare SAVED.mat]

--spectra writes 'name v1 ... vN' per mesh (area-scaled eigenvalues divided
by 4 pi, the units of the signatures' spectra). --compare reads a
`tpr-eval-local --save-matrices` file and prints, over the models both hold,
the largest relative difference between its spectra and these. Needs NumPy
and SciPy (Debian: python3-numpy, python3-scipy). Eigensolver: SciPy's
shift-invert ARPACK around sigma = -1e-3 / (area scale), which converges to
the smallest eigenvalues of L x = lambda M x.
"""
import argparse
import math
import os
import sys

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla


def load_mesh(path):
    if path.endswith('.off'):
        t = open(path).read().split()
        i = 1 if t[0] == 'OFF' else 0
        nv, nf = int(t[i]), int(t[i + 1])
        i += 3
        v = np.array(t[i:i + 3 * nv], float).reshape(nv, 3)
        i += 3 * nv
        faces = []
        for _ in range(nf):
            k = int(t[i])
            faces.append([int(x) for x in t[i + 1:i + 1 + k]])
            i += 1 + k
    else:
        verts, faces = [], []
        for line in open(path):
            p = line.split()
            if not p:
                continue
            if p[0] == 'v':
                verts.append([float(x) for x in p[1:4]])
            elif p[0] == 'f':
                faces.append([int(x.split('/')[0]) - 1 for x in p[1:]])
        v = np.array(verts, float)
    tris = []
    for f in faces:  # fan-triangulate polygons
        for j in range(1, len(f) - 1):
            tris.append([f[0], f[j], f[j + 1]])
    return v, np.array(tris, int)


def fem_matrices(v, f):
    """Cotangent stiffness L and consistent mass M of linear FEM."""
    n = len(v)
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1)
    rows, cols, lv, mv = [], [], [], []
    corners = [(0, 1, 2), (1, 2, 0), (2, 0, 1)]
    for a, b, c in corners:  # angle at corner a faces edge (b, c)
        u = v[f[:, b]] - v[f[:, a]]
        w = v[f[:, c]] - v[f[:, a]]
        cot = (u * w).sum(1) / np.maximum(np.linalg.norm(np.cross(u, w), axis=1), 1e-300)
        for x, y in ((b, c), (c, b)):
            rows.append(f[:, x]); cols.append(f[:, y])
            lv.append(-0.5 * cot); mv.append(area / 12.0)
    for a in range(3):
        rows.append(f[:, a]); cols.append(f[:, a])
        lv.append(np.zeros(len(f))); mv.append(area / 6.0)
    r, c = np.concatenate(rows), np.concatenate(cols)
    off = sp.coo_matrix((np.concatenate(lv), (r, c)), shape=(n, n)).tocsr()
    diag = -np.asarray(off.sum(axis=1)).ravel()
    stiff = off + sp.diags(diag)
    mass = sp.coo_matrix((np.concatenate(mv), (r, c)), shape=(n, n)).tocsr()
    return stiff, mass, area.sum()


def spectrum(path, count):
    v, f = load_mesh(path)
    used = np.unique(f)
    remap = -np.ones(len(v), int)
    remap[used] = np.arange(len(used))
    v, f = v[used], remap[f]
    stiff, mass, total = fem_matrices(v, f)
    ncomp = sp.csgraph.connected_components(stiff != 0, directed=False)[0]
    k = count + ncomp
    if len(v) <= 600:
        import scipy.linalg as la
        vals = la.eigh(stiff.toarray(), mass.toarray(), eigvals_only=True)
    else:
        sigma = -1e-3 * 4 * math.pi / total
        vals = sla.eigsh(stiff.tocsc(), k=k, M=mass.tocsc(), sigma=sigma,
                         which='LM', return_eigenvectors=False, tol=1e-10)
    vals = np.sort(vals)[ncomp:ncomp + count]
    return vals * total / (4 * math.pi)


def scores(dist, labels):
    n = len(labels)
    labels = np.array(labels)
    nn = ft = st = dcg = 0.0
    q = 0
    for i in range(n):
        rel_total = (labels == labels[i]).sum() - 1
        if rel_total == 0:
            continue
        q += 1
        d = dist[i].copy()
        d[i] = np.inf
        order = np.argsort(d, kind='stable')[:n - 1]
        rel = (labels[order] == labels[i]).astype(float)
        nn += rel[0]
        ft += rel[:rel_total].sum() / rel_total
        st += rel[:2 * rel_total].sum() / rel_total
        disc = np.ones(n - 1)
        disc[1:] = 1 / np.log2(np.arange(2, n))
        dcg += (rel * disc).sum() / disc[:rel_total].sum()
    return nn / q, ft / q, st / q, dcg / q


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('manifest')
    ap.add_argument('--eigenvalues', type=int, default=50)
    ap.add_argument('--spectra')
    ap.add_argument('--compare')
    a = ap.parse_args()
    root = os.path.dirname(os.path.abspath(a.manifest))
    names, labels, spectra = [], [], []
    for line in open(a.manifest):
        p = line.split()
        if len(p) < 2:
            continue
        names.append(p[0]); labels.append(p[1])
        spectra.append(spectrum(os.path.join(root, p[0]), a.eigenvalues))
        print(f'  {len(names)} {p[0]}', file=sys.stderr, end='\r')
    s = np.array(spectra)
    if a.spectra:
        with open(a.spectra, 'w') as out:
            for name, row in zip(names, s):
                out.write(name + ' ' + ' '.join(f'{x:.10g}' for x in row) + '\n')
    x = s / np.arange(1, a.eigenvalues + 1)
    dist = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(-1))
    nn, ft, st, dcg = scores(dist, labels)
    print(f'ShapeDNA-{a.eigenvalues} (linear FEM, consistent mass, area, 1/i, L2) '
          f'{a.manifest}: {len(names)} models, NN {nn:.3f} FT {ft:.3f} ST {st:.3f} '
          f'DCG {dcg:.3f}')
    if a.compare:
        t = open(a.compare).read().split('\n')
        count = int(t[1])
        theirs = {}
        for i in range(count):
            name = t[2 + i].split('\t')[0]
            vals = [float(y) for y in t[2 + count + i].split()[1:]]
            theirs[name] = vals
        worst, where = 0.0, ''
        for name, row in zip(names, s):
            other = theirs.get(name) or theirs.get(os.path.join(root, name))
            if other is None:
                continue
            m = min(len(other), len(row))
            rel = np.abs(np.array(other[:m]) - row[:m]) / row[:m]
            if rel.max() > worst:
                worst, where = rel.max(), f'{name} eigenvalue {rel.argmax() + 1}'
        print(f'largest relative difference to {a.compare}: {worst:.4g} ({where})')


if __name__ == '__main__':
    main()
