"""The GIL and Python threads: queries and builds release the GIL, several Python threads cast
rays at one scene and at several scenes at once, geometry is added while other threads trace,
and progress callables (which need the GIL on the build's worker threads) run while other
threads hold it. Each scenario runs in a child interpreter with a timeout, so that a deadlock
fails the test instead of hanging the run."""
import os
import subprocess
import sys
import textwrap

import pytest

from conftest import import_slimrt

slimrt = import_slimrt()

TIMEOUT = 120  # seconds; each scenario takes a few seconds

PRELUDE = textwrap.dedent("""
    import sys, threading
    import numpy as np
    import slimrt
    sys.path.insert(0, {tests!r})
    from conftest import icosphere, random_rays

    def run_threads(targets):
        errors = []
        def wrap(f):
            def g():
                try:
                    f()
                except BaseException as e:  # reported by the parent
                    errors.append(repr(e))
            return g
        th = [threading.Thread(target=wrap(f)) for f in targets]
        for x in th:
            x.start()
        for x in th:
            x.join()
        assert not errors, errors
""")


def run_scenario(body):
    code = PRELUDE.format(tests=os.path.dirname(os.path.abspath(__file__))) + \
        textwrap.dedent(body) + "\nprint('ok')\n"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [os.path.dirname(slimrt.__file__)] + [p for p in [env.get("PYTHONPATH")] if p])
    try:
        p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                           text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        pytest.fail(f"no answer within {TIMEOUT} s: a deadlock")
    assert p.returncode == 0 and p.stdout.strip().endswith("ok"), p.stdout + p.stderr


def test_cast_rays_from_threads_on_one_scene_and_on_several():
    run_scenario("""
        v, t = icosphere(4)
        rng = np.random.default_rng(1)
        rays = random_rays(rng, v.min(0), v.max(0), 30000)
        scenes = []
        for k, config in enumerate(["clbvh-compact", "bvh8-tri4v", "qbvh8-tri4i"]):
            s = slimrt.RaycastingScene(config, threads=1 + k % 2)
            s.add_triangles(v + np.float32(k), t)
            scenes.append(s)
        # References, one at a time (each scene builds on its first query).
        ref = [s.cast_rays(rays + np.float32([k, k, k, 0, 0, 0]), nthreads=1)
               for k, s in enumerate(scenes)]
        occ = [s.test_occlusions(rays + np.float32([k, k, k, 0, 0, 0])) for k, s in
               enumerate(scenes)]
        assert np.isfinite(ref[0]["t_hit"]).sum() > 1000
        results = {}

        def caster(k, i):
            def f():
                r = rays + np.float32([k, k, k, 0, 0, 0])
                for _ in range(3):
                    results[(k, i)] = (scenes[k].cast_rays(r), scenes[k].test_occlusions(r),
                                       scenes[k].count_intersections(r[:2000]))
            return f
        # 4 threads on scene 0, 2 on each of the others, all at once.
        run_threads([caster(0, i) for i in range(4)] +
                    [caster(k, i) for k in (1, 2) for i in range(2)])
        for (k, i), (r, o, c) in results.items():
            for key in ("t_hit", "geometry_ids", "primitive_ids", "primitive_uvs",
                        "primitive_normals"):
                np.testing.assert_array_equal(r[key], ref[k][key])
            np.testing.assert_array_equal(o, occ[k])
            assert c.max() >= 2
        assert len(results) == 8
    """)


def test_add_geometry_while_other_threads_trace():
    # A thread adds meshes (each add drops the built scene) while others trace, with a progress
    # callable in Python: the tracing threads keep the scene they started with, and the builds
    # they trigger call back into Python from the build's threads while the adder holds the GIL.
    run_scenario("""
        v, t = icosphere(3)
        calls = [0]

        def progress(phase, done, total):
            calls[0] += 1
        s = slimrt.RaycastingScene("clbvh-compact", progress=progress)
        s.add_triangles(v, t)
        rays = np.array([[0, 0, 5, 0, 0, -1]] * 5000, np.float32)
        stop = threading.Event()
        seen = []

        def tracer():
            while not stop.is_set():
                r = s.cast_rays(rays)
                assert (r["t_hit"] == r["t_hit"][0]).all()
                seen.append(float(r["t_hit"][0]))

        def adder():
            try:
                for k in range(1, 9):
                    s.add_triangles(v + np.float32([0, 0, 0.25 * k]), t)
                    s.memory()  # builds now, with the GIL taken by the callable
            finally:
                stop.set()
        run_threads([tracer, tracer, adder])
        assert s.geometry_count == 9 and calls[0] > 0
        assert s.cast_rays(rays[:1])["t_hit"][0] == np.float32(5 - 1 - 0.25 * 8)
        # Every answer is the top of one of the scenes that existed.
        tops = {np.float32(5 - 1 - 0.25 * k) for k in range(9)}
        assert seen and all(np.float32(x) in tops for x in seen), set(seen)
    """)


def test_progress_callable_and_errors_while_the_gil_is_released():
    # A progress callable that queries another scene works (nested parallel work from inside a
    # build); one that queries the scene it is building gets a RuntimeError (the scene is not
    # built until it returns), which the query that built raises. Bad rays raise ValueError from
    # threads that run at the same time as builds with Python callables.
    run_scenario("""
        v, t, _ = slimrt.load_triangles("terrain:64")
        other = slimrt.RaycastingScene("bvh8-tri4v")
        other.add_triangles(*icosphere(2))
        probe = np.array([[0, 0, 5, 0, 0, -1]] * 3000, np.float32)
        answers = []

        def nested(phase, done, total):
            answers.append(float(other.cast_rays(probe)["t_hit"][0]))
        s = slimrt.RaycastingScene("clbvh-compact", progress=nested)
        s.add_triangles(v, t)
        assert s.stats()["triangles"] == len(t)
        assert answers and all(a == 4.0 for a in answers)

        box = {}

        def reentrant(phase, done, total):
            box["s"].cast_rays(probe[:1])
        s2 = slimrt.RaycastingScene("bvh8-tri4v", progress=reentrant)
        box["s"] = s2
        s2.add_triangles(v, t)
        try:
            s2.cast_rays(probe[:1])
            raise AssertionError("no error")
        except RuntimeError as e:
            assert "progress callable cannot use the scene" in str(e), e

        bad = probe.copy()
        bad[7, 2] = np.nan

        def builder(k):
            def f():
                calls = []
                s = slimrt.RaycastingScene(["bvh8-tri4v", "clbvh-compact"][k % 2],
                                           progress=lambda p, d, n: calls.append(p))
                s.add_triangles(v + np.float32(k), t)
                s.stats()
                assert calls
            return f

        def bad_rays():
            for _ in range(20):
                try:
                    other.cast_rays(bad)
                    raise AssertionError("no error")
                except ValueError as e:
                    assert "ray 7" in str(e)
        run_threads([builder(k) for k in range(4)] + [bad_rays, bad_rays])
    """)
