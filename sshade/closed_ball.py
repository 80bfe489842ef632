"""The closed-ball property of a Voronoi decomposition, checked (paper §3.1; Edelsbrunner
& Shah 1997): compiled kernels of :func:`sshade.remesh.remesh`'s check-and-repair rounds,
called one after another from Python (a kernel calling kernels recompiles their code).

On the high-res mesh with every boundary loop coned to a virtual vertex: every region a
disk, every two adjacent regions meeting along one arc, every three at one point; a
failing region, pair or triple gets one repair candidate (its vertex farthest from its
seed). :func:`closed_ball` is one full round, :func:`closed_ball_local` a round limited
to the regions that changed. Details: docs/implementation.md ("Implementation notes:
sshade/closed_ball.py").
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .mesh.halfedge import halfedges

__all__ = ["closed_ball", "closed_ball_full", "closed_ball_holds", "closed_ball_local", "vertex_faces",
           "warm_kernels"]

# Pairs and triples of region labels are numbered through open-addressing hash tables
# (int64 keys, -1 = empty slot, linear probing, Fibonacci hashing).
_HASH_MULT = -7046029254386353131  # 0x9E3779B97F4A7C15 as int64


@njit(cache=True, inline="always")
def _slot(keys, key, mask):
    i = ((key * _HASH_MULT) >> 24) & mask
    while keys[i] != -1 and keys[i] != key:
        i = (i + 1) & mask
    return i


@njit(cache=True, inline="always")
def _table_id(keys, ids, key, mask, nxt):
    """Id of ``key`` in the table (keys, ids), inserting it with id ``nxt`` if new.
    Returns (id, next free id)."""
    i = _slot(keys, key, mask)
    if keys[i] == -1:
        keys[i] = key
        ids[i] = nxt
        nxt += 1
    return ids[i], nxt


@njit(cache=True)
def _table(n_keys):
    cap = 16
    while cap < 2 * n_keys:
        cap *= 2
    return np.full(cap, -1, np.int64), np.empty(cap, np.int64), cap - 1


@njit(cache=True, inline="always")
def _find(parent, x):
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@njit(cache=True, inline="always")
def _link(parent, arc, cyc, p, x, y):
    """Cross edges x and y of pair p linked by a two-label face: one path fewer, or a
    closed loop when they are already connected (union-find ``parent``)."""
    arc[p] -= 1
    r1, r2 = _find(parent, x), _find(parent, y)
    if r1 == r2:
        cyc[p] = True
    else:
        parent[r1] = r2


@njit(cache=True, inline="always")
def _better(best, g, v, dist):
    """Keep the first vertex of largest distance per group (ties: the earlier one)."""
    if best[g] < 0 or dist[v] > dist[best[g]]:
        best[g] = v


@njit(cache=True, inline="always")
def _take(best, m, dist, pick):
    """Mark the kept vertex of every group < m (if not a seed: distance > 0) in ``pick``
    and reset ``best``."""
    for g in range(m):
        if best[g] >= 0 and dist[best[g]] > 0:
            pick[best[g]] = True
        best[g] = -1


@njit(cache=True, inline="always")
def _sorted3(l0, l1, l2):
    """The three labels in increasing order."""
    a = min(l0, l1, l2)
    c = max(l0, l1, l2)
    return a, l0 + l1 + l2 - a - c, c


@njit(cache=True, inline="always")
def _face_kind(lab, Fc, f, chi):
    """Number of distinct labels of face f (1, 2 or 3); a one-label face adds 1 to its
    region's chi."""
    l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
    if l0 == l1 and l1 == l2:
        chi[l0] += 1
        return 1
    if l0 != l1 and l1 != l2 and l0 != l2:
        return 3
    return 2


def closed_ball_full(Fc, Ec, FEc, lab, dist, n, nlab):
    """One round of closed-ball checks with the repair candidates (the rules:
    docs/implementation.md, "Implementation notes: sshade/closed_ball.py").

    lab : (n + loops,) labels with the cone vertices as their own regions.
    Returns (bad, cand, f3): whether the property fails, the sorted unique seed
    candidates and the faces carrying three labels, in face order."""
    chi, kind, ncross, n3 = _region_euler(Fc, Ec, lab, nlab)
    pair, parent, arc, np_ = _cross_pairs(Ec, lab, nlab, ncross)
    cyc = np.zeros(np_, np.bool_)
    f3, tri, nt = _link_faces(Fc, FEc, lab, nlab, kind, n3, pair, parent, arc, cyc)
    tcnt = np.bincount(tri, minlength=nt).astype(np.int64)
    bad = bool((chi != 1).any() or (arc != 1).any() or cyc.any() or (tcnt != 1).any())
    if not bad:
        return False, np.empty(0, np.int64), f3
    pick = _repair_candidates(Fc, Ec, lab, dist, n, nlab, chi, pair, arc, cyc, np_, f3, tri, tcnt, nt)
    return True, np.flatnonzero(pick), f3


@njit(cache=True)
def _region_euler(Fc, Ec, lab, nlab):
    """1. regions are disks: chi = V - E + F == 1 per label. Returns chi (nlab,), the
    number of distinct labels of each face (nf,) int8, the cross-edge count and the
    count of faces with three labels."""
    ne, nf = Ec.shape[0], Fc.shape[0]
    chi = np.zeros(nlab, np.int64)
    for v in range(lab.shape[0]):
        chi[lab[v]] += 1
    ncross = 0
    for e in range(ne):
        if lab[Ec[e, 0]] == lab[Ec[e, 1]]:
            chi[lab[Ec[e, 0]]] -= 1
        else:
            ncross += 1
    kind = np.empty(nf, np.int8)  # number of distinct labels of each face
    n3 = 0
    for f in range(nf):
        kind[f] = _face_kind(lab, Fc, f, chi)
        n3 += kind[f] == 3
    return chi, kind, ncross, n3


def _cross_pairs(Ec, lab, nlab, ncross):
    """2. two regions meet along one arc: the cross edges of a pair, linked through the
    faces with two labels, form paths and cycles; one arc <=> (edges - links) == 1 and
    no link closes a cycle (union-find over the cross edges). Returns each edge's pair
    id (-1 inside a region), the union-find parents, the per-pair cross-edge counts
    (links are subtracted by :func:`_link_faces`) and the number of pairs."""
    ne = Ec.shape[0]
    pair = np.full(ne, -1, np.int64)
    parent = np.empty(ne, np.int64)
    # a table sized for the pairs of a triangulation (about 3 per region) fits in the
    # cache, where one sized by the cross edges (a bound on the pairs) does not
    np_ = _pair_ids(Ec, lab, nlab, min(ncross, 4 * nlab), pair, parent)
    if np_ < 0:  # more pairs than that
        np_ = _pair_ids(Ec, lab, nlab, ncross, pair, parent)
    arc = np.bincount(pair[pair >= 0], minlength=np_).astype(np.int64)  # cross edges - links: 1 for a single path
    return pair, parent, arc, np_


@njit(cache=True)
def _pair_ids(Ec, lab, nlab, n_keys, pair, parent):
    """Fill ``pair`` (each cross edge's pair id) and ``parent`` (itself) for the edges
    ``Ec``; returns the number of pairs, or -1 (``pair`` partly filled) when there are
    more than ``n_keys``."""
    pkeys, pids, pmask = _table(n_keys)
    np_ = 0
    for e in range(Ec.shape[0]):
        a, b = lab[Ec[e, 0]], lab[Ec[e, 1]]
        if a != b:
            pair[e], np_ = _table_id(pkeys, pids, min(a, b) * nlab + max(a, b), pmask, np_)
            if np_ > n_keys:
                return -1
            parent[e] = e
    return np_


@njit(cache=True)
def _link_faces(Fc, FEc, lab, nlab, kind, n3, pair, parent, arc, cyc):
    """Links of the cross edges through the two-label faces (updates ``arc``, ``cyc``,
    ``parent`` in place) and 3. three regions meet at one point: each label triple on
    exactly one face. Returns the three-label faces (n3,), their triple ids and the
    number of triples."""
    tkeys, tids, tmask = _table(n3)
    f3 = np.empty(n3, np.int64)
    tri = np.empty(n3, np.int64)
    nt = 0
    j = 0
    for f in range(Fc.shape[0]):
        if kind[f] == 2:
            e1 = -1
            for k in range(3):
                e = FEc[f, k]
                if pair[e] >= 0:
                    if e1 < 0:
                        e1 = e
                    else:
                        _link(parent, arc, cyc, pair[e], e1, e)
        elif kind[f] == 3:
            l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
            a, b, c = _sorted3(l0, l1, l2)
            f3[j] = f
            tri[j], nt = _table_id(tkeys, tids, (a * nlab + b) * nlab + c, tmask, nt)
            j += 1
    return f3, tri, nt


@njit(cache=True)
def _repair_candidates(Fc, Ec, lab, dist, n, nlab, chi, pair, arc, cyc, np_, f3, tri, tcnt, nt):
    """Candidates: per bad region / pair / triple, its farthest vertex from its seed
    (first one met on ties, in vertex / edge / face order), if not a seed already.
    Returns a (n,) bool mask."""
    pick = np.zeros(n, np.bool_)
    best = np.full(max(nlab, np_, nt), -1, np.int64)
    for v in range(n):
        if chi[lab[v]] != 1:
            _better(best, lab[v], v, dist)
    _take(best, nlab, dist, pick)
    for e in range(Ec.shape[0]):
        p = pair[e]
        if p >= 0 and (arc[p] != 1 or cyc[p]):
            for k in range(2):
                if Ec[e, k] < n:
                    _better(best, p, Ec[e, k], dist)
    _take(best, np_, dist, pick)
    for j in range(f3.shape[0]):
        t = tri[j]
        if tcnt[t] != 1:
            for k in range(3):
                if Fc[f3[j], k] < n:
                    _better(best, t, Fc[f3[j], k], dist)
    _take(best, nt, dist, pick)
    return pick


@njit(cache=True)
def closed_ball_holds(Fc, FEc, lab, nlab, ne):
    """Whether the closed-ball property holds, from one pass over the faces (the common
    case once the sampling is dense enough; :func:`_closed_ball_full` otherwise).

    On the coned mesh every edge lies on exactly two faces, so the edge counts follow
    from the faces: a region's same-label edges number (3 F1 + F2) / 2 (F1: faces of
    that label only, F2: faces with it twice), so 2 chi = 2 V - F1 - F2; and a pair's
    cross edges minus its two-label faces (the number of its arcs that are paths) is
    half its three-label faces F3. The property holds iff 2 chi == 2 for every
    region, F3 == 2 and no closed loop for every pair (union-find over the cross edges
    linked by the two-label faces: a pair whose edges only form loops has F3 == 0 but
    is caught by its loop), and every label triple is on one face.
    Returns (holds, f3 = the three-label faces in face order)."""
    nf = Fc.shape[0]
    chi2 = np.zeros(nlab, np.int64)
    for v in range(lab.shape[0]):
        chi2[lab[v]] += 2
    parent = np.arange(ne)
    f3 = np.empty(nf, np.int64)
    n3 = 0
    for f in range(nf):
        l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
        if l0 == l1 and l1 == l2:
            chi2[l0] -= 1
        elif l0 != l1 and l1 != l2 and l0 != l2:
            f3[n3] = f
            n3 += 1
        else:
            chi2[l1 if (l0 == l1 or l1 == l2) else l0] -= 1
            # the two cross edges: the sides whose end points have different labels
            e1 = FEc[f, 0] if l0 != l1 else FEc[f, 1]
            e2 = FEc[f, 2] if l2 != l0 else FEc[f, 1]
            r1, r2 = _find(parent, e1), _find(parent, e2)
            if r1 == r2:
                return False, f3[:n3]  # a loop
            parent[r1] = r2
    for r in range(nlab):
        if chi2[r] != 2:
            return False, f3[:n3]
    keys, ids, mask = _table(3 * n3)
    cnt = np.zeros(3 * n3, np.int64)
    np_ = 0
    for j in range(n3):
        f = f3[j]
        l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
        a, b, c = _sorted3(l0, l1, l2)
        for key in (a * nlab + b, b * nlab + c, a * nlab + c):
            p, np_ = _table_id(keys, ids, key, mask, np_)
            cnt[p] += 1
    for p in range(np_):
        if cnt[p] != 2:
            return False, f3[:n3]
    tkeys, _, tmask = _table(n3)
    for j in range(n3):
        f = f3[j]
        l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
        a, b, c = _sorted3(l0, l1, l2)
        i = _slot(tkeys, (a * nlab + b) * nlab + c, tmask)
        if tkeys[i] != -1:
            return False, f3[:n3]  # a triple on two faces
        tkeys[i] = (a * nlab + b) * nlab + c
    return True, f3[:n3].copy()


def closed_ball(Fc, Ec, FEc, lab, dist, n, nlab):
    """One round of closed-ball checks (the rules: docs/implementation.md, "Implementation notes:
    sshade/closed_ball.py"): the one-pass test, and the full check with repair candidates
    when it fails. Returns (bad, cand, f3)."""
    ok, f3 = closed_ball_holds(Fc, FEc, lab, nlab, Ec.shape[0])
    if ok:
        return False, np.empty(0, np.int64), f3
    return closed_ball_full(Fc, Ec, FEc, lab, dist, n, nlab)


@njit(cache=True, nogil=True)
def vertex_faces(Fc, n):
    """The faces around each vertex ``v < n`` of ``Fc`` (m, 3) int64, as a CSR:
    ``(ptr (n + 1,) int64, idx (c,) int32)``, the faces of ``v`` in increasing order at
    ``idx[ptr[v]:ptr[v + 1]]`` (cone vertices ``>= n`` left out). Face indices must fit
    in int32 (meshes of fewer than 2**31 faces)."""
    ptr = np.zeros(n + 1, np.int64)
    for f in range(Fc.shape[0]):
        for k in range(3):
            if Fc[f, k] < n:
                ptr[Fc[f, k] + 1] += 1
    for v in range(n):
        ptr[v + 1] += ptr[v]
    idx = np.empty(ptr[n], np.int32)
    pos = ptr[:n].copy()
    for f in range(Fc.shape[0]):
        for k in range(3):
            v = Fc[f, k]
            if v < n:
                idx[pos[v]] = f
                pos[v] += 1
    return ptr, idx


@njit(cache=True)
def _marked(mark):
    """Indices of the set entries of a bool array, increasing; clears them."""
    cnt = 0
    for i in range(mark.shape[0]):
        if mark[i]:
            cnt += 1
    out = np.empty(cnt, np.int64)
    j = 0
    for i in range(mark.shape[0]):
        if mark[i]:
            out[j] = i
            mark[i] = False
            j += 1
    return out


@njit(cache=True)
def _touched(Fc, FEc, vf_ptr, vf_idx, lab, n, ne, in_a):
    """The vertices of the regions ``in_a`` (a (nlab,) bool mask), the faces with one of
    them and those faces' edges, each in increasing order: ``(vs, fs, es)`` int64."""
    fmark = np.zeros(Fc.shape[0], np.bool_)
    vmark = np.zeros(n, np.bool_)
    for v in range(n):
        if in_a[lab[v]]:
            vmark[v] = True
            for p in range(vf_ptr[v], vf_ptr[v + 1]):
                fmark[vf_idx[p]] = True
    vs = _marked(vmark)
    fs = _marked(fmark)
    emark = np.zeros(ne, np.bool_)
    for f in fs:
        for k in range(3):
            emark[FEc[f, k]] = True
    return vs, fs, _marked(emark)


@njit(cache=True)
def _local_euler(Fc, Ec, lab, nlab, in_a, vs, fs, es):
    """chi (nlab,) of the regions in A (other entries partial), the number of labels of
    each face of ``fs`` (int8), the cross edges of ``es`` involving A and the
    three-label faces of ``fs`` (counts)."""
    chi = np.zeros(nlab, np.int64)
    for v in vs:
        chi[lab[v]] += 1
    ncross = 0
    for e in es:
        a, b = lab[Ec[e, 0]], lab[Ec[e, 1]]
        if a == b:
            chi[a] -= 1
        elif in_a[a] or in_a[b]:
            ncross += 1
    kind = np.empty(fs.shape[0], np.int8)
    n3 = 0
    for i in range(fs.shape[0]):
        kind[i] = _face_kind(lab, Fc, fs[i], chi)
        n3 += kind[i] == 3
    return chi, kind, ncross, n3


@njit(cache=True)
def _lower_bound(a, x):
    """The first index i of the increasing int array ``a`` with ``a[i] >= x`` (``len(a)``
    when none): ``np.searchsorted(a, x)``, written as a loop (numba's compiles in 1 s)."""
    lo, hi = 0, a.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def _local_pairs(Fc, Ec, FEc, lab, nlab, in_a, fs, es, kind, ncross):
    """The pairs involving A: each edge of ``es``'s pair id (-1: none of them), the
    per-pair (cross edges - links) and closed-loop flags (as :func:`_cross_pairs` and
    :func:`_link_faces`, over ``es`` and ``fs``)."""
    pkeys, pids, pmask = _table(ncross)
    pair = np.full(es.shape[0], -1, np.int64)
    parent = np.arange(es.shape[0])
    np_ = 0
    for i in range(es.shape[0]):
        a, b = lab[Ec[es[i], 0]], lab[Ec[es[i], 1]]
        if a != b and (in_a[a] or in_a[b]):
            pair[i], np_ = _table_id(pkeys, pids, min(a, b) * nlab + max(a, b), pmask, np_)
    arc = np.zeros(np_, np.int64)
    for i in range(es.shape[0]):
        if pair[i] >= 0:
            arc[pair[i]] += 1
    cyc = np.zeros(np_, np.bool_)
    for i in range(fs.shape[0]):
        if kind[i] != 2:
            continue
        i1 = -1
        for k in range(3):
            i2 = _lower_bound(es, FEc[fs[i], k])  # every edge of a face of fs is in es
            if pair[i2] >= 0:
                if i1 < 0:
                    i1 = i2
                else:
                    _link(parent, arc, cyc, pair[i2], i1, i2)
    return pair, arc, cyc, np_


@njit(cache=True)
def _local_triples(Fc, lab, nlab, in_a, fs, kind, n3):
    """The three-label faces of ``fs`` whose triple involves A, in face order, their
    triple ids and the per-triple face counts."""
    tkeys, tids, tmask = _table(n3)
    f3 = np.empty(n3, np.int64)
    tri = np.empty(n3, np.int64)
    nt = 0
    j = 0
    for i in range(fs.shape[0]):
        if kind[i] != 3:
            continue
        f = fs[i]
        l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
        if in_a[l0] or in_a[l1] or in_a[l2]:
            a, b, c = _sorted3(l0, l1, l2)
            f3[j] = f
            tri[j], nt = _table_id(tkeys, tids, (a * nlab + b) * nlab + c, tmask, nt)
            j += 1
    tcnt = np.zeros(nt, np.int64)
    for i in range(j):
        tcnt[tri[i]] += 1
    return f3[:j].copy(), tri[:j].copy(), tcnt


@njit(cache=True)
def _any_bad_region(chi, in_a):
    """Whether a region of A (``in_a``) has chi != 1."""
    for r in range(chi.shape[0]):
        if in_a[r] and chi[r] != 1:
            return True
    return False


def closed_ball_local(Fc, Ec, FEc, vf_ptr, vf_idx, lab, dist, n, nlab, in_a):
    """The closed-ball check restricted to the regions ``in_a`` (A) and the pairs and
    triples involving one of them (docs/implementation.md, "Implementation notes: sshade/closed_ball.py").

    Parameters
    ----------
    Fc, Ec, FEc : the coned mesh's faces (m + b, 3), edges (e, 2), face edges (m + b, 3),
        int64 (:class:`sshade.remesh.MeshTopology`). vf_ptr, vf_idx : :func:`vertex_faces`.
    lab : (n + loops,) int32 labels (cone vertices their own regions); dist : (n,)
        float64 distances to the seeds. n : vertices; nlab : labels. in_a : (nlab,) bool,
        the regions A (a cone vertex's region is left out of A: one vertex, always a
        disk; its pairs and triples with the regions of A are judged).

    Returns
    -------
    bad : whether a region of A, or a pair or triple involving A, fails.
    cand : (c,) int64 sorted unique repair candidates, the same vertices
        :func:`closed_ball_full` picks for those.
    f3u : (u,) int64 the faces of the triples involving A carried by one face, in face
        order (the low-res faces to check for flips).
    """
    in_a = in_a.copy()
    in_a[lab[n:]] = False  # a cone vertex's region: a disk, judged through its pairs
    vs, fs, es = _touched(Fc, FEc, vf_ptr, vf_idx, lab, n, Ec.shape[0], in_a)
    chi, kind, ncross, n3 = _local_euler(Fc, Ec, lab, nlab, in_a, vs, fs, es)
    pair, arc, cyc, np_ = _local_pairs(Fc, Ec, FEc, lab, nlab, in_a, fs, es, kind, ncross)
    f3, tri, tcnt = _local_triples(Fc, lab, nlab, in_a, fs, kind, n3)
    bad, pick = _local_candidates(Fc, Ec, lab, dist, n, nlab, in_a, vs, es, chi, pair, arc, cyc, f3, tri, tcnt)
    return bad, np.flatnonzero(pick), f3[tcnt[tri] == 1]


@njit(cache=True)
def _local_candidates(Fc, Ec, lab, dist, n, nlab, in_a, vs, es, chi, pair, arc, cyc, f3, tri, tcnt):
    """The verdict of :func:`closed_ball_local` and its repair candidates: ``(bad, pick)``,
    ``pick`` a (n,) bool mask (the rules of :func:`_repair_candidates`, over A)."""
    np_, nt = arc.shape[0], tcnt.shape[0]
    best = np.full(max(nlab, np_, nt), -1, np.int64)
    pick = np.zeros(n, np.bool_)
    bad = _any_bad_region(chi, in_a)
    for v in vs:  # regions of A that are not disks
        if chi[lab[v]] != 1:
            _better(best, lab[v], v, dist)
    _take(best, nlab, dist, pick)
    for i in range(es.shape[0]):  # pairs that are not one arc
        p = pair[i]
        if p >= 0 and (arc[p] != 1 or cyc[p]):
            bad = True
            for k in range(2):
                if Ec[es[i], k] < n:
                    _better(best, p, Ec[es[i], k], dist)
    _take(best, np_, dist, pick)
    for j in range(f3.shape[0]):  # triples on more than one face
        t = tri[j]
        if tcnt[t] != 1:
            bad = True
            for k in range(3):
                if Fc[f3[j], k] < n:
                    _better(best, t, Fc[f3[j], k], dist)
    _take(best, nt, dist, pick)
    return bad, pick


def warm_kernels() -> None:
    """Compile (or load from numba's cache) every kernel of this module with the argument
    types :func:`sshade.remesh.remesh` passes, on a closed tetrahedron labelled twice: two
    regions (the property fails: the repair path) and four (it holds)."""
    Fc = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
    he = halfedges(Fc, 4)
    Ec, FEc = he.E, he.FE
    ptr, idx = vertex_faces(Fc, 4)
    for lab in (np.array([0, 0, 1, 1], np.int32), np.arange(4, dtype=np.int32)):
        nlab = int(lab.max()) + 1
        closed_ball(Fc, Ec, FEc, lab, np.zeros(4), 4, nlab)
        closed_ball_full(Fc, Ec, FEc, lab, np.zeros(4), 4, nlab)
        closed_ball_local(Fc, Ec, FEc, ptr, idx, lab, np.zeros(4), 4, nlab, np.ones(nlab, np.bool_))
