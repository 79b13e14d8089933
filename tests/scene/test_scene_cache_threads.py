"""What a scene derives and keeps is computed once, whatever the threads asking for it.

Coverage tiles run on threads of one process and share the scene: its cached properties
(the dihedra, the ray caster, ...) and what later stages keep on it (:meth:`Scene.memo`)
must be built once, not once per thread that arrives while it is being built (Python 3.12
dropped ``functools.cached_property``'s lock).
"""

import dataclasses
import pickle
import threading
import time

import numpy as np
import pytest

from wavepaths.scene import load_scene
from wavepaths.scene.model import Scene, scene_cached_property

THREADS = 8


def _race(fn, n=THREADS):
    """Run ``fn`` on ``n`` threads released at once; their results in thread order."""
    start = threading.Barrier(n)
    out = [None] * n
    errors = []

    def run(i):
        start.wait()
        try:
            out[i] = fn()
        except BaseException as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    return out


def test_memo_computes_once_for_racing_threads():
    scene = load_scene("street_canyon")
    calls = []

    def make():
        calls.append(threading.get_ident())
        time.sleep(0.05)  # long enough for every thread to arrive while it runs
        return np.arange(3)

    got = _race(lambda: scene.memo("slow", make))
    assert len(calls) == 1
    assert all(g is got[0] for g in got)


def test_memo_keeps_at_most_keep_values_of_a_kind_oldest_dropped_first():
    scene = load_scene("street_canyon")
    for i in range(5):
        assert scene.memo(("mask", i), lambda i=i: i * 10, keep=3) == i * 10
    kept = sorted(k[1] for k in scene.__dict__["_memo"] if isinstance(k, tuple) and k[0] == "mask")
    assert kept == [2, 3, 4]
    # another kind is not touched
    scene.memo(("other", 0), lambda: "x", keep=1)
    assert scene.memo(("mask", 4), lambda: pytest.fail("recomputed")) == 40


def test_a_cached_property_is_built_once_for_racing_threads(monkeypatch):
    scene = load_scene("street_canyon")
    calls = []
    original = Scene.__dict__["bounds"].func

    def slow_bounds(self):
        calls.append(1)
        time.sleep(0.05)
        return original(self)

    prop = scene_cached_property(slow_bounds)
    prop.__set_name__(Scene, "bounds")
    monkeypatch.setattr(Scene, "bounds", prop)
    got = _race(lambda: scene.bounds)
    assert len(calls) == 1
    assert all(g is got[0] for g in got)
    np.testing.assert_array_equal(got[0], original(scene))


def test_values_of_different_keys_do_not_wait_for_each_other():
    """A value's computation may itself run threads that need another value of the scene
    (one lock per value, not per scene): no deadlock."""
    scene = load_scene("street_canyon")

    def outer():
        box = {}
        t = threading.Thread(target=lambda: box.setdefault("inner", scene.memo("inner", lambda: 7)))
        t.start()
        t.join(timeout=10)
        assert not t.is_alive(), "deadlock: the inner value waited for the outer one's lock"
        return box["inner"] + 1

    assert scene.memo("outer", outer) == 8


def test_a_pickled_or_replaced_scene_gets_its_own_locks_and_keeps_working():
    scene = load_scene("street_canyon")
    scene.memo("kept", lambda: 5)
    scene.dihedra  # noqa: B018 - built before pickling
    back = pickle.loads(pickle.dumps(scene))
    assert back._value_locks is not scene._value_locks
    assert back.memo("kept", lambda: pytest.fail("recomputed")) == 5
    assert len(back.dihedra.face_ptr) == len(scene.dihedra.face_ptr)
    assert _race(lambda: back.memo("new", lambda: 6), n=4) == [6] * 4
    other = dataclasses.replace(scene, source="copy")
    assert other._value_locks is not scene._value_locks
    assert other.memo("kept", lambda: 9) == 9  # derived values are not carried over
