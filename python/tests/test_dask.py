"""libmr.dask on a LocalCluster of 2 workers: 40 small frames, 4 of them bad; a worker is killed
mid-run; every good output exists exactly once and is complete; a second run skips them all."""

import os
import signal
import subprocess
import threading
import time

import numpy as np
import pytest

import libmr

distributed = pytest.importorskip("distributed", reason="python3-distributed not installed")
import libmr.dask  # noqa: E402

MR = os.environ.get("MR_CLI")
GUARD_S = 300.0  # deadlock guard only, never a timing assertion
GOOD, H, W = 36, 90, 120


def scene():
    s = libmr.Scene()  # the scattering core (a sun), so that each frame takes a little while
    s.medium.sigma_t_per_m = (0.02, 0.02, 0.02)
    s.medium.layer_top_m = 30.0
    s.lighting.sun = libmr.Sun(direction_to_sun=(0.4, 0.7, 0.5), irradiance=(3, 3, 3))
    s.lighting.sky_radiance = (0.6, 0.65, 0.7)
    s.render.quality = libmr.Quality.draft
    s.render.backend = libmr.Backend.cpu
    s.render.threads = 1
    return s


def make_frames(folder):
    folder.mkdir()
    rng = np.random.default_rng(40)
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float32)
    good = []
    for i in range(GOOD):
        photo = np.stack([(xs + 3 * i) % W / W, ys / H, np.full_like(xs, 0.3)], axis=-1).astype(np.float32)
        photo += rng.normal(0, 0.02, photo.shape).astype(np.float32)
        depth = (3.0 + ys * (0.5 + 0.01 * i)).astype(np.float32)
        depth[:10] = np.inf  # sky at the top
        libmr.write_image(folder / f"f{i:03d}.jpg", np.clip(photo, 0, 1))
        libmr.write_image(folder / f"f{i:03d}_depth.exr", depth, pixel_type="float")
        good.append(folder / f"f{i:03d}.jpg")
    depth = np.full((H, W), 10.0, np.float32)
    (folder / "bad_garbage.jpg").write_bytes(b"not a jpeg at all" * 64)
    libmr.write_image(folder / "bad_garbage_depth.exr", depth, pixel_type="float")
    libmr.write_image(folder / "tmp.png", np.full((H, W, 3), 0.5, np.float32))
    data = (folder / "tmp.png").read_bytes()
    (folder / "tmp.png").unlink()
    (folder / "bad_truncated.png").write_bytes(data[: len(data) // 3])
    libmr.write_image(folder / "bad_truncated_depth.exr", depth, pixel_type="float")
    libmr.write_image(folder / "bad_nodepth.jpg", np.full((H, W, 3), 0.5, np.float32))
    libmr.write_image(folder / "bad_size.jpg", np.full((H, W, 3), 0.5, np.float32))
    libmr.write_image(folder / "bad_size_depth.exr", depth[:-1], pixel_type="float")
    bad = [folder / n for n in ("bad_garbage.jpg", "bad_truncated.png", "bad_nodepth.jpg", "bad_size.jpg")]
    return good, bad


def test_batch_on_local_cluster_survives_a_killed_worker(tmp_path):
    good, bad = make_frames(tmp_path / "frames")
    out = tmp_path / "foggy"
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
    client = distributed.Client(cluster)
    try:
        result = {}

        def run():
            try:
                result["summary"] = libmr.dask.fog_frames(tmp_path / "frames", out, scene=scene(),
                                                          scheduler=client)
            except BaseException as e:  # noqa: BLE001 - reported by the assertions below
                result["error"] = e

        batch = threading.Thread(target=run)
        batch.start()
        deadline = time.monotonic() + GUARD_S
        while time.monotonic() < deadline and batch.is_alive():
            if out.exists() and sum(1 for n in os.listdir(out) if n.endswith("_fog.jpg")) >= 3:
                break
            time.sleep(0.02)
        victim = sorted(client.run(os.getpid).values())[0]
        killed_mid_run = batch.is_alive()
        os.kill(victim, signal.SIGKILL)
        batch.join(GUARD_S)
        assert not batch.is_alive()
        assert "error" not in result, result.get("error")
        assert killed_mid_run, "the batch finished before a worker could be killed"
        summary = result["summary"]
        assert summary.done + summary.skipped == GOOD, str(summary)
        assert sorted(p for p, _ in summary.failed) == sorted(str(b) for b in bad), str(summary)
        reasons = dict(summary.failed)
        assert "bad_garbage.jpg" in reasons[str(bad[0])]
        assert "no depth map" in reasons[str(bad[2])]
        assert "120x89" in reasons[str(bad[3])]
        # exactly the good outputs, once each, no temporaries or partial files
        assert sorted(os.listdir(out)) == sorted(f"{g.stem}_fog.jpg" for g in good)
        # complete, and what `mr fog` writes for the same frames and scene, pixel for pixel
        if MR and os.path.exists(MR):
            libmr.save_scene(tmp_path / "scene.json", scene())
            subprocess.run([MR, "fog", str(tmp_path / "frames"), "--scene", str(tmp_path / "scene.json"),
                            "--out-dir", str(tmp_path / "cli"), "-q"], check=False)
        for g in good:
            output = out / f"{g.stem}_fog.jpg"
            assert libmr.probe_image(output).software == libmr.dask.OUTPUT_SOFTWARE
            written = libmr.read_image(output)
            assert written.shape == (H, W, 3)
            if MR and os.path.exists(MR):
                np.testing.assert_array_equal(written, libmr.read_image(tmp_path / "cli" / output.name))

        # a second run (a resumed batch) skips every finished output and reports the bad ones
        again = libmr.dask.fog_frames(tmp_path / "frames", out, scene=scene(), scheduler=client)
        assert (again.done, again.skipped, len(again.failed)) == (0, GOOD, len(bad)), str(again)
    finally:
        client.close()
        cluster.close()


def test_plan_reports_collisions_and_outputs_that_are_inputs(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for d in ("a", "b"):
        libmr.write_image(tmp_path / d / "x.jpg", np.zeros((4, 4, 3), np.float32))
        libmr.write_image(tmp_path / d / "x_depth.exr", np.ones((4, 4), np.float32))
    frames, failed = libmr.dask.plan_frames([str(tmp_path / "a" / "x.jpg"), str(tmp_path / "b" / "x.jpg")],
                                            tmp_path / "out")
    assert frames == [] and len(failed) == 2 and all("would also be written" in r for _, r in failed)
    frames, failed = libmr.dask.plan_frames([str(tmp_path / "a" / "x.jpg")], tmp_path / "a",
                                            suffix="_depth", format="exr")
    assert frames == [] and "is an input" in failed[0][1]


def test_stale_temporaries_of_dead_writers_are_removed(tmp_path):
    dead = tmp_path / ".x_fog.mr-tmp-999999999-1.jpg"  # no such process
    alive = tmp_path / f".y_fog.mr-tmp-{os.getpid()}-1.jpg"
    other = tmp_path / "z.jpg"
    for p in (dead, alive, other):
        p.write_bytes(b"x")
    removed = libmr.dask.remove_stale_temporaries(tmp_path, local=True)
    assert removed == [str(dead)]
    assert alive.exists() and other.exists()
    assert libmr.dask.remove_stale_temporaries(tmp_path, local=False) == []  # not a day old


def test_own_local_cluster_and_progress_lines(tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(3):
        libmr.write_image(folder / f"p{i}.png", np.full((12, 16, 3), 0.2 * i, np.float32))
        libmr.write_image(folder / f"p{i}_depth.exr", np.full((12, 16), 5.0 + i, np.float32),
                          pixel_type="float")
    lines = []
    s = libmr.Scene()
    s.lighting.sky_radiance = (0.7, 0.7, 0.7)
    summary = libmr.dask.fog_frames(folder, tmp_path / "out", scene=s, n_workers=1, progress=True,
                                    progress_every=1, log=lines.append)
    assert (summary.done, summary.skipped, summary.failed) == (3, 0, []), str(summary)
    assert sum(1 for line in lines if "frames (" in line) == 3 and "3 done" in lines[-1]
    assert sorted(os.listdir(tmp_path / "out")) == ["p0_fog.png", "p1_fog.png", "p2_fog.png"]
    # sky light only: the closed form C = I T + L (1 - T), T = exp(-sigma_t d), within 8-bit rounding
    t = np.exp(-np.array(s.medium.sigma_t_per_m) * 6.0)
    expected = 0.2 * t + 0.7 * (1 - t)
    out = libmr.read_image(tmp_path / "out" / "p1_fog.png", colorspace="srgb_rolloff")
    np.testing.assert_allclose(out[0, 0], expected, rtol=0, atol=4e-3)
