"""The GIL is released during renders: two Python threads render at the same time, and another
thread cancels a render. No wall-clock assertions: the timeouts below only turn a deadlock (what
a render holding the GIL would cause) into a failure instead of a hang."""

import threading

import numpy as np
import pytest

import libmr

DEADLOCK_GUARD_S = 120.0


def scene_with_sun():
    # A sun forces the full scattering core (row by row, reporting 'render' progress).
    s = libmr.Scene()
    s.medium.layer_top_m = 40.0
    s.lighting.sun = libmr.Sun(direction_to_sun=(0.3, 0.8, 0.4), irradiance=(3, 3, 3))
    s.lighting.sky_radiance = (0.5, 0.5, 0.5)
    s.render.quality = libmr.Quality.draft
    s.render.backend = libmr.Backend.cpu
    return s


def frame(rng, h=96, w=128):
    photo = rng.random((h, w, 3), dtype=np.float32)
    depth = np.broadcast_to(np.linspace(2.0, 60.0, h, dtype=np.float32)[:, None], (h, w)).copy()
    return photo, depth


def test_two_threads_render_at_the_same_time(rng):
    # Each render, once started, waits inside its own progress callback until the other render
    # has started too. Both finish only if both run concurrently: a render holding the GIL
    # would keep the other thread (and the callbacks from libmr's worker threads) out.
    started = {"a": threading.Event(), "b": threading.Event()}
    results, errors = {}, {}

    def run(me, other):
        token = libmr.CancelToken()

        def progress(stage, done, total):
            assert 0 <= done <= total
            if stage == "render" and not started[me].is_set():
                started[me].set()
                if not started[other].wait(DEADLOCK_GUARD_S):
                    token.request()

        token.set_progress(progress, 0.0)
        photo, depth = frame(np.random.default_rng(ord(me)))
        try:
            results[me] = libmr.fog(photo, depth, scene_with_sun(), cancel=token)
        except Exception as e:  # noqa: BLE001 (reported below)
            errors[me] = e

    threads = [threading.Thread(target=run, args=p) for p in (("a", "b"), ("b", "a"))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(DEADLOCK_GUARD_S * 2)
    assert not any(t.is_alive() for t in threads)
    assert errors == {}, errors
    assert set(results) == {"a", "b"}
    # the concurrent renders equal renders made one at a time
    for me in "ab":
        photo, depth = frame(np.random.default_rng(ord(me)))
        alone = libmr.fog(photo, depth, scene_with_sun())
        np.testing.assert_array_equal(results[me].composite, alone.composite)


def test_another_thread_cancels_a_render(rng):
    token = libmr.CancelToken()
    in_render, proceed = threading.Event(), threading.Event()
    stages = []

    def progress(stage, done, total):
        stages.append((stage, done, total))
        if stage == "render" and not in_render.is_set():
            in_render.set()
            proceed.wait(DEADLOCK_GUARD_S)  # hold the render here until it has been cancelled

    token.set_progress(progress, 0.0)
    outcome = {}

    def run():
        photo, depth = frame(rng)
        try:
            outcome["result"] = libmr.fog(photo, depth, scene_with_sun(), cancel=token)
        except libmr.Error as e:
            outcome["error"] = e

    t = threading.Thread(target=run)
    t.start()
    assert in_render.wait(DEADLOCK_GUARD_S)
    token.request()  # from this thread, while the other is inside the C++ render
    proceed.set()
    t.join(DEADLOCK_GUARD_S)
    assert not t.is_alive()
    assert "result" not in outcome
    assert isinstance(outcome["error"], libmr.CancelledError)
    assert outcome["error"].code == libmr.ErrorCode.cancelled
    # it stopped early: the render stage never reported completion
    render = [(d, n) for s, d, n in stages if s == "render"]
    assert render and all(d < n for d, n in render)
    # a token stays requested until reset; reset, it renders normally
    with pytest.raises(libmr.CancelledError):
        libmr.fog(*frame(rng), scene_with_sun(), cancel=token)
    token.reset()
    token.set_progress(None)
    assert libmr.fog(*frame(rng), scene_with_sun(), cancel=token).composite.shape == (96, 128, 3)


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # printed on purpose
def test_exception_in_progress_callback_cancels(rng):
    token = libmr.CancelToken()

    def progress(stage, done, total):
        raise RuntimeError("stop here")

    token.set_progress(progress, 0.0)
    with pytest.raises(libmr.CancelledError):
        libmr.fog(*frame(rng), scene_with_sun(), cancel=token)
