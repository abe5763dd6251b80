"""`frame(t)` decodes into the arrays of an earlier frame once Python has let go of them, and
never into arrays (or views of them) that are still reachable."""

import numpy as np

import dlgs
from test_roundtrip import assert_same


def ptr(a):
    return a.__array_interface__["data"][0]


def test_released_frames_are_reused_and_exact(dyn_exact):
    r, fresh = dlgs.open(dyn_exact), dlgs.open(dyn_exact)
    f = r.frame(0.1, language=True)
    before = ptr(f["positions"])
    del f
    for t in (0.2345, 0.9, 1.3, 0.05):  # GOP 0, GOP 1, back to GOP 0
        g = r.frame(t, language=True)
        assert ptr(g["positions"]) == before  # the released arrays, decoded into again
        assert_same(g, fresh.frame(t, language=True))
        assert list(g) == list(fresh.frame(t, language=True))  # same keys, same order
        del g


def test_arrays_still_reachable_are_not_overwritten(dyn_exact):
    r = dlgs.open(dyn_exact)
    kept = r.frame(0.1)                       # the whole dict kept
    want = {k: v.copy() for k, v in kept.items()}
    column = r.frame(0.2)["positions"][:, 0]  # only a view of one array kept
    column_want = column.copy()
    for t in (0.3, 0.4, 0.5, 1.1):
        g = r.frame(t)
        assert ptr(g["positions"]) not in (ptr(kept["positions"]),)
        del g
    assert_same(kept, want)
    assert np.array_equal(column, column_want)
    # A read-only array is not written either.
    ro = r.frame(0.6)
    ro_want = {k: v.copy() for k, v in ro.items()}
    for v in ro.values():
        v.setflags(write=False)
    keep = dict(ro)
    del ro
    r.frame(0.7)
    assert_same(keep, ro_want)


def test_a_plain_loop_alternates_between_two_sets(dyn_exact):
    """`f = r.frame(t)` in a loop holds the previous frame during the call: the one before it
    is free and decoded into, so a loop cycles through two sets of arrays."""
    r, fresh = dlgs.open(dyn_exact), dlgs.open(dyn_exact)
    ptrs = []
    f = None
    for i in range(6):
        f = r.frame(0.1 * i)
        ptrs.append(ptr(f["positions"]))
    a, b = ptrs[:2]
    assert a != b and ptrs == [a, b, a, b, a, b]
    assert_same(f, fresh.frame(0.5))
