"""The compiled kernels that replaced scipy in the extension (components.py, kdtree.py,
distance_transform.py) give exactly scipy's answers, ties included: the same labels in the same
order, the same neighbours in the same order with the same float64 distances, the same nearest
pixel and the same boxes. scipy is a test dependency only; without it these comparisons skip."""
import numpy as np
import pytest

from detp_bake.components import connected_components, label_boxes
from detp_bake.distance_transform import distance_transform
from detp_bake.kdtree import KDTree, query_groups

csgraph = pytest.importorskip("scipy.sparse.csgraph")
sparse = pytest.importorskip("scipy.sparse")
spatial = pytest.importorskip("scipy.spatial")
ndimage = pytest.importorskip("scipy.ndimage")


def _scipy_components(n, a, b):
    graph = sparse.coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(n, n))
    return csgraph.connected_components(graph, directed=False)


@pytest.mark.parametrize("n, edges", [(1, 0), (2, 0), (5, 1), (40, 20), (40, 60), (300, 250)])
def test_components_are_scipys_labels_in_scipys_order(n, edges):
    rng = np.random.default_rng(n * 1000 + edges)
    for _ in range(20):
        a, b = rng.integers(0, n, edges), rng.integers(0, n, edges)
        count, label = connected_components(n, a, b)
        want_count, want = _scipy_components(n, a, b)
        assert count == want_count
        np.testing.assert_array_equal(label, want)


def test_components_of_a_chain_given_backwards_and_of_self_loops():
    n = 7
    count, label = connected_components(n, np.arange(n - 1)[::-1] + 1, np.arange(n - 1)[::-1])
    assert count == 1 and not label.any()
    count, label = connected_components(3, [2, 2], [2, 0])  # a self-loop; 2 joins 0
    np.testing.assert_array_equal(label, [0, 1, 0])
    assert count == 2
    assert connected_components(0, [], [])[0] == 0
    with pytest.raises(ValueError, match="outside"):
        connected_components(3, [0], [3])


def _cloud(kind, n, rng):
    if kind == "random":
        return rng.random((n, 3)).astype(np.float32)
    if kind == "lattice":  # many points at the same distance, and duplicates
        return rng.integers(0, 5, (n, 3)).astype(np.float32)
    side = int(np.ceil(np.sqrt(n)))  # a flat chart's texels
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side), [0.0]), -1).reshape(-1, 3)
    return (grid * 0.125 + 2.0).astype(np.float32)


@pytest.mark.parametrize("kind", ["random", "lattice", "grid"])
@pytest.mark.parametrize("balanced", [True, False])
def test_kdtree_gives_ckdtrees_neighbours_in_its_order(kind, balanced):
    rng = np.random.default_rng(7)
    for n, k in [(1, 1), (2, 3), (17, 5), (600, 24), (2500, 40), (20000, 3000)]:  # the last meets > 256 nodes
        pts = _cloud(kind, n, rng)
        queries = np.concatenate([pts[rng.integers(0, len(pts), 30)], rng.random((30, 3)) * 3])
        ours = KDTree(pts, balanced=balanced, compact=balanced)
        theirs = spatial.cKDTree(pts, balanced_tree=balanced, compact_nodes=balanced)
        for bound in (np.inf, 0.3, 1.0):
            dist, idx = ours.query(queries, k, distance_upper_bound=bound)
            want_d, want_i = theirs.query(queries, k=k, distance_upper_bound=bound)
            np.testing.assert_array_equal(idx, want_i.reshape(idx.shape), err_msg=f"{kind} n={n} k={k}")
            np.testing.assert_array_equal(dist, want_d.reshape(dist.shape))


def test_query_groups_asks_each_groups_own_tree():
    """query_groups over groups of every kind, some lying on each other, some empty or not asked:
    what a KDTree of each group alone gives, its indices shifted by the group's start."""
    rng = np.random.default_rng(3)
    parts = [_cloud(("random", "lattice", "grid")[g % 3], n, rng) for g, n in enumerate([1, 0, 17, 600, 5, 2500, 40, 3])]
    sizes = [len(p) for p in parts]  # a grid of n points rounds up to a square
    start = np.cumsum([0] + sizes[:-1])
    k = np.minimum(24, np.maximum(sizes, 1))
    bound = np.array([np.inf, 1.0, 0.3, 0.2, np.inf, 0.5, 1.0, 0.1])
    asked = [g for g in range(len(sizes)) if sizes[g] and g != 6]
    x = [np.concatenate([parts[g][rng.integers(0, sizes[g], 20)], rng.random((5, 3)) * 3]) for g in asked]
    group = np.repeat(asked, [len(q) for q in x])
    dist, idx = query_groups(np.concatenate(parts), start, sizes, np.concatenate(x), group, k, bound)
    assert dist.shape == idx.shape == (len(group), 24)
    for g, q in zip(asked, x):
        rows = group == g
        want_d, want_i = KDTree(parts[g]).query(q, k[g], distance_upper_bound=bound[g])
        got_i = np.where(idx[rows] < sum(sizes), idx[rows] - start[g], sizes[g])
        np.testing.assert_array_equal(got_i[:, :k[g]], want_i, err_msg=f"group {g}")
        np.testing.assert_array_equal(dist[rows, :k[g]], want_d)
        assert np.isinf(dist[rows, k[g]:]).all() and (idx[rows, k[g]:] == sum(sizes)).all()


def test_kdtree_with_no_points_or_no_queries():
    dist, idx = KDTree(np.zeros((0, 3))).query(np.ones((2, 3)), 3)
    assert dist.shape == (2, 3) and np.isinf(dist).all() and (idx == 0).all()
    dist, idx = KDTree(np.ones((4, 3))).query(np.zeros((0, 3)), 2)
    assert dist.shape == (0, 2)
    with pytest.raises(ValueError, match="at least 1"):
        KDTree(np.ones((4, 3))).query(np.zeros((1, 3)), 0)


@pytest.mark.parametrize("share", [0.01, 0.1, 0.5, 0.95])
def test_distance_transform_is_scipys_with_its_nearest_pixel_on_ties(share):
    rng = np.random.default_rng(int(share * 100))
    for _ in range(150):
        h, w = rng.integers(1, 24, 2)
        background = rng.random((h, w)) > share
        background.flat[rng.integers(background.size)] = False  # at least one feature pixel
        far, (rows, cols) = distance_transform(background)
        want, (want_r, want_c) = ndimage.distance_transform_edt(background, return_indices=True)
        np.testing.assert_array_equal(far, want)
        np.testing.assert_array_equal(rows, want_r)
        np.testing.assert_array_equal(cols, want_c)


def test_distance_transform_of_one_pixel_and_of_no_feature():
    far, (rows, cols) = distance_transform(np.array([[False]]))
    assert far[0, 0] == 0 and rows[0, 0] == 0 and cols[0, 0] == 0
    far, (rows, cols) = distance_transform(np.ones((2, 3), bool))
    assert np.isinf(far).all() and (rows == -1).all() and (cols == -1).all()
    far, _ = distance_transform(np.array([[True, True, False]]))
    np.testing.assert_array_equal(far, [[2.0, 1.0, 0.0]])


def test_label_boxes_are_find_objects():
    rng = np.random.default_rng(3)
    for _ in range(200):
        h, w = rng.integers(1, 16, 2)
        label = rng.integers(-1, rng.integers(1, 9), (h, w))
        assert label_boxes(label) == ndimage.find_objects(label + 1)
    assert label_boxes(np.full((3, 3), -1)) == []
    assert label_boxes(np.array([[2]])) == [None, None, (slice(0, 1), slice(0, 1))]
