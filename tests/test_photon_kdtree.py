"""The photon map's balanced kd-tree (renderer/photon/photon_map.h) against
brute force: k-nearest and range queries on uniform, clustered (caustic-like)
and duplicated points. Distances are float32 computed in the tree's order
((dx^2 + dy^2) + dz^2), so the squared distances must agree bit for bit;
the neighbour sets must agree except for points tied with the k-th distance
(which of equidistant points is kept is the tree's documented tie rule)."""
import numpy as np
import pytest

from radiometer import _core


def brute_d2(points, q):
    d = points - q[None, :].astype(np.float32)
    return (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2]


def point_sets(seed):
    rng = np.random.default_rng(seed)
    uniform = rng.random((5000, 3), dtype=np.float32)
    # A caustic-like cluster: most points in a tiny disc on a plane, plus a sparse background.
    disc = np.zeros((4000, 3), np.float32)
    r = 0.01 * np.sqrt(rng.random(4000))
    a = 2 * np.pi * rng.random(4000)
    disc[:, 0], disc[:, 2] = r * np.cos(a), r * np.sin(a)
    clustered = np.concatenate([disc, rng.random((1000, 3), dtype=np.float32) - 0.5]).astype(np.float32)
    # Duplicates and points sharing coordinates (ties in the median split).
    dup = np.repeat(rng.integers(0, 4, (300, 3)).astype(np.float32) * 0.25, 5, axis=0)
    return {"uniform": uniform, "clustered": clustered, "duplicates": dup}


@pytest.mark.parametrize("kind", ["uniform", "clustered", "duplicates"])
@pytest.mark.parametrize("k,r_max", [(1, np.inf), (8, np.inf), (50, 0.05), (120, 0.2)])
def test_knn_matches_brute_force(kind, k, r_max):
    pts = point_sets(1)[kind]
    tree = _core.PhotonMap(pts, threads=2)
    assert tree.size == len(pts)
    rng = np.random.default_rng(2)
    queries = np.concatenate([rng.random((100, 3), dtype=np.float32) - 0.25, pts[rng.integers(0, len(pts), 100)]])
    idx, d2 = tree.knn(queries, k, r_max)
    r2 = np.float32(r_max) * np.float32(r_max) if np.isfinite(r_max) else np.inf
    for i, q in enumerate(queries):
        bd = brute_d2(pts, q)
        inside = np.flatnonzero(bd <= r2)
        want = np.sort(bd[inside])[:k]
        got = d2[i][idx[i] >= 0]
        np.testing.assert_array_equal(got, want, err_msg=f"{kind} query {i}: squared distances")
        assert np.all(np.diff(got) >= 0), "nearest first"
        # Every point strictly nearer than the k-th is reported, each once.
        if len(got):
            kth = got[-1]
            strictly = set(inside[bd[inside] < kth].tolist())
            ids = idx[i][idx[i] >= 0]
            assert len(set(ids.tolist())) == len(ids)
            assert strictly <= set(ids.tolist()), f"{kind} query {i}: a nearer point is missing"
            np.testing.assert_array_equal(bd[ids], got)


@pytest.mark.parametrize("kind", ["uniform", "clustered", "duplicates"])
@pytest.mark.parametrize("r", [0.0, 0.003, 0.05, 0.3])
def test_range_matches_brute_force(kind, r):
    pts = point_sets(3)[kind]
    tree = _core.PhotonMap(pts)
    rng = np.random.default_rng(4)
    queries = np.concatenate([rng.random((60, 3), dtype=np.float32) - 0.25, pts[rng.integers(0, len(pts), 60)]])
    r2 = np.float32(r) * np.float32(r)
    counts = tree.range_count(queries, r, threads=2)
    for i, q in enumerate(queries):
        ids, d2 = tree.range(q, r)
        bd = brute_d2(pts, q)
        want = set(np.flatnonzero(bd <= r2).tolist())
        assert set(ids.tolist()) == want and len(ids) == len(want), f"{kind} query {i}"
        np.testing.assert_array_equal(d2, bd[ids])
        assert counts[i] == len(want)


def test_build_is_independent_of_threads_and_empty_tree_works():
    pts = point_sets(5)["clustered"]
    q = pts[:50] + np.float32(1e-3)
    a = _core.PhotonMap(pts, threads=1).knn(q, 20)
    b = _core.PhotonMap(pts, threads=8).knn(q, 20)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    empty = _core.PhotonMap(np.zeros((0, 3), np.float32))
    idx, d2 = empty.knn(q[:2], 3)
    assert np.all(idx == -1) and np.all(np.isinf(d2))
    assert len(empty.range(q[0], 1.0)[0]) == 0


def _reference_layout(pts):
    """Jensen's balanced tree as photon_map.h defines it, in plain Python:
    the node of a range is its median along the axis of largest extent of
    its points' bounding box, ties ordered by input index, the lower half
    left. Every slot is the median of exactly one range, so the layout is a
    function of the points alone, whatever selection algorithm the build
    uses. Returns the input index at each slot."""
    out = np.empty(len(pts), np.int64)

    def node(ids, lo):
        if len(ids) == 0:
            return
        p = pts[ids]
        ext = p.max(axis=0) - p.min(axis=0)
        a = 0 if (ext[0] >= ext[1] and ext[0] >= ext[2]) else (1 if ext[1] >= ext[2] else 2)
        order = ids[np.lexsort((ids, p[:, a]))]
        mid = len(ids) // 2
        out[lo + mid] = order[mid]
        node(order[:mid], lo)
        node(order[mid + 1:], lo + mid + 1)

    node(np.arange(len(pts)), 0)
    return out


def _range_all_order(layout):
    """The order in which PhotonMap::range visits the slots of `layout`
    when every point is within the radius (its explicit stack: the node,
    then the upper half, then the lower)."""
    order, stack = [], [(0, len(layout))]
    while stack:
        lo, hi = stack.pop()
        if lo >= hi:
            continue
        mid = (lo + hi) // 2
        order.append(layout[mid])
        stack.append((lo, mid))
        stack.append((mid + 1, hi))
    return np.array(order)


@pytest.mark.parametrize("kind", ["uniform", "clustered", "duplicates"])
def test_tree_layout_is_the_balanced_tree(kind):
    """The build's layout (seen through the order in which range() returns
    every point) equals the reference balanced tree's, duplicates (ties on
    every axis) included."""
    pts = point_sets(4)[kind]
    tree = _core.PhotonMap(pts, threads=1)
    ids, _ = tree.range(pts.mean(axis=0).tolist(), 1e9)
    np.testing.assert_array_equal(ids, _range_all_order(_reference_layout(pts)))


def test_tree_layout_is_independent_of_threads():
    """The parallel build (top levels split in parallel, then subtrees as
    tasks; photon_map.cpp) gives the same layout as one thread, at a size
    where both parallel stages run; a tree that differs in one slot fails."""
    rng = np.random.default_rng(5)
    pts = np.concatenate([rng.random((150_000, 3), dtype=np.float32),
                          np.float32(0.01) * rng.random((150_000, 3), dtype=np.float32)])
    centre = pts.mean(axis=0).tolist()
    want, _ = _core.PhotonMap(pts, threads=1).range(centre, 1e9)
    for threads in (2, 3, 8):
        got, _ = _core.PhotonMap(pts, threads=threads).range(centre, 1e9)
        np.testing.assert_array_equal(got, want)
    # Power: two points swapped give another tree, and another order.
    swapped = pts.copy()
    swapped[[0, 1]] = swapped[[1, 0]]
    other, _ = _core.PhotonMap(swapped, threads=2).range(centre, 1e9)
    assert not np.array_equal(other, want)


def test_bad_query_arguments_raise():
    tree = _core.PhotonMap(np.zeros((4, 3), np.float32))
    with pytest.raises(ValueError, match="k must be"):
        tree.knn(np.zeros((1, 3), np.float32), 0)
    with pytest.raises(ValueError, match="shape"):
        tree.knn(np.zeros((1, 2), np.float32), 1)
    with pytest.raises(ValueError, match="r must be"):
        tree.range([0, 0, 0], -1.0)
