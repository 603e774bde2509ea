"""UCT with virtual visits, redundancy-aware claims, max backup and id assignment (hand-built trees)."""

import math

import numpy as np
import pytest

from fmctd_dist.search.select import backup, claimable, descend, select_batch, uct_scores, uct_select
from fmctd_dist.search.tree import EMPTY, ROOT, Tree, assign_ids, empty_tree

A = 5
C = math.sqrt(2.0)


def make_tree(a: int = A, terminal_depth: int = 3, capacity: int = 64) -> Tree:
    return empty_tree(capacity, a, tokens=2, token_dim=4, plan_frames=10, terminal_depth=terminal_depth)


def grow(tree: Tree, parent: int, slot: int, value: float = 0.0, visits: int = 0) -> int:
    """Attach one child by hand (what add_nodes does, minus payloads)."""
    n = tree.num_nodes
    tree.parent[n], tree.slot[n], tree.depth[n] = parent, slot, tree.depth[parent] + 1
    tree.children[parent, slot] = n
    tree.value[n], tree.visits[n] = value, visits
    tree.num_nodes += 1
    return n


def full_root(values=(0.0,) * A, visits=(0,) * A) -> Tree:
    tree = make_tree()
    for s in range(A):
        grow(tree, ROOT, s, values[s], visits[s])
    tree.visits[ROOT] = 1
    return tree


def rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


def test_unvisited_child_first_even_with_lower_value():
    tree = full_root(values=(0.9, 0.1, 0.8, 0.2, 0.7), visits=(3, 0, 2, 0, 1))
    assert uct_select(tree, ROOT, C, 1.0) == 3  # unvisited: slots 1 and 3; 3 has the higher value


def test_unvisited_ties_go_to_lowest_slot():
    tree = full_root(visits=(1, 0, 1, 0, 0))
    assert uct_select(tree, ROOT, C, 1.0) == 1


def test_uct_formula_matches_reference():
    tree = full_root(values=(0.5, 0.2, 0.0, 0.0, 0.1), visits=(4, 1, 2, 3, 1))
    tree.virtual[1:6] = [0.0, 2.0, 0.0, 0.0, 1.0]
    w = 0.5
    n = np.array([4, 1 + 1.0, 2, 3, 1 + 0.5])
    want = np.array([0.5, 0.2, 0.0, 0.0, 0.1]) + C * np.sqrt(np.log(n.sum() + 1e-6) / (n + 1e-6))
    np.testing.assert_allclose(uct_scores(tree, ROOT, C, w), want)
    assert uct_select(tree, ROOT, C, w) == int(np.argmax(want))


def test_small_total_visits_give_no_nan():
    tree = full_root(values=(0.0, 0.3, 0.0, 0.0, 0.0))
    tree.virtual[1:6] = 1.0
    scores = uct_scores(tree, ROOT, C, 0.1)  # N = 0.5 < 1: log term clamped at 0
    assert np.all(np.isfinite(scores))
    assert uct_select(tree, ROOT, C, 0.1) == 1


def test_fresh_tree_batch_claims_distinct_root_slots_and_stops_early():
    tree = make_tree()
    cand = select_batch(tree, 10, rng(), w=1.0)
    assert sorted(cand.slots.tolist()) == [0, 1, 2, 3, 4]
    assert cand.parents.tolist() == [ROOT] * 5
    assert cand.attempts == 5 and cand.wasted == 0  # nothing left to claim after 5
    assert tree.claimed[ROOT].all()


def test_slot_choice_is_random_but_seeded():
    a = select_batch(make_tree(), 3, rng(1)).slots.tolist()
    b = select_batch(make_tree(), 3, rng(1)).slots.tolist()
    others = {tuple(select_batch(make_tree(), 3, rng(s)).slots.tolist()) for s in range(2, 12)}
    assert a == b and len(others) > 1


def test_virtual_visits_spread_a_batch_over_children():
    tree = full_root()
    cand = select_batch(tree, 7, rng(), w=1.0)
    assert sorted(set(cand.parents.tolist())) == [1, 2, 3, 4, 5]
    assert cand.wasted == 0
    np.testing.assert_array_equal(tree.virtual[1:6], [2, 2, 1, 1, 1])
    assert tree.visits[1:6].tolist() == [0] * 5  # delayed update: only virtual counts move


def test_zero_weight_sends_every_descent_down_one_path():
    tree = full_root(values=(0.0, 0.0, 0.4, 0.0, 0.0))
    cand = select_batch(tree, 7, rng(), w=0.0)
    assert cand.parents.tolist() == [3] * 5  # node 3 = slot 2, the best fresh child
    assert cand.wasted == 2  # its slots are all claimed, nothing else is reachable


def test_no_slot_claimed_twice_with_redundancy_awareness():
    tree = full_root()
    for s in range(A):  # a third level so that descents go deeper
        grow(tree, 1 + s, 0)
    cand = select_batch(tree, 40, rng(3), w=1.0)
    pairs = list(zip(cand.parents.tolist(), cand.slots.tolist()))
    assert len(pairs) == len(set(pairs)) > A


def test_without_redundancy_awareness_slots_are_claimed_again():
    tree = make_tree()
    cand = select_batch(tree, 12, rng(), redundancy_aware=False)
    pairs = list(zip(cand.parents.tolist(), cand.slots.tolist()))
    assert len(pairs) == 12 and len(set(pairs)) < 12  # no early stop, duplicates


def test_leaf_parallel_adds_a_virtual_visits():
    tree = full_root()
    select_batch(tree, 1, rng(), leaf_parallel=True)
    assert tree.virtual[1:6].tolist() == [float(A), 0, 0, 0, 0]


def test_terminal_node_is_a_wasted_descent():
    tree = make_tree(terminal_depth=1)
    for s in range(A):
        grow(tree, ROOT, s)
    assert not claimable(tree, 1, True).any()
    assert descend(tree, rng(), C, 1.0, True, False) is None
    assert select_batch(tree, 4, rng()).attempts == 0  # no open slot anywhere: nothing to try


def test_backup_is_max_and_counts_each_parent_once():
    tree = full_root(values=(0.1, 0.0, 0.0, 0.0, 0.0), visits=(1, 1, 0, 0, 0))
    tree.value[ROOT] = 0.1
    tree.virtual[1:3] = 3.0
    a = grow(tree, 1, 0, value=0.6)
    b = grow(tree, 1, 4, value=0.3)
    c = grow(tree, 2, 1, value=0.2)
    backup(tree, np.array([1, 1, 2]))
    assert tree.value[1] == 0.6 and tree.value[2] == 0.2 and tree.value[ROOT] == 0.6
    assert tree.visits[ROOT] == 3 and tree.visits[1] == 2 and tree.visits[2] == 2
    assert tree.visits[[a, b, c]].tolist() == [0, 0, 0]  # new leaves stay unvisited
    assert tree.virtual[1] == 0 and tree.virtual[2] == 0


def test_backup_takes_max_not_mean():
    tree = full_root(values=(0.2, 0.9, 0.0, 0.0, 0.0))
    backup(tree, np.array([ROOT]))
    assert tree.value[ROOT] == 0.9  # max, not mean


def test_assign_ids_sorted_by_parent_then_slot():
    tree = full_root()  # nodes 0..5
    asg = assign_ids(tree, np.array([3, 1, 3, 1, 3]), np.array([4, 2, 0, 2, 4]))
    assert asg.parent.tolist() == [1, 1, 3, 3, 3]
    assert asg.slot.tolist() == [2, 2, 0, 4, 4]
    assert asg.node.tolist() == [6, 6, 7, 8, 8]
    assert asg.copy.tolist() == [0, 1, 0, 0, 1]
    assert asg.order.tolist() == [1, 3, 2, 0, 4]
    assert asg.new_nodes.tolist() == [6, 7, 8]


def test_assign_ids_refuses_to_overflow():
    tree = make_tree(capacity=3)
    with pytest.raises(ValueError, match="capacity"):
        assign_ids(tree, np.zeros(3, int), np.arange(3))


def test_empty_slots_are_marked_empty():
    tree = make_tree()
    assert (tree.children[ROOT] == EMPTY).all() and tree.num_nodes == 1
