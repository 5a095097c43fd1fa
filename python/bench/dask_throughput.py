"""Dask throughput on 2 local workers against `mr fog -j 2` on the same frames (issue 15).

    PYTHONPATH=build/python /usr/bin/python3 python/bench/dask_throughput.py build/cli/mr \
        [--frames 20] [--width 1920 --height 1080] [--scratch /tmp/dask_bench]

Writes `frames` JPEG photos with float EXR depth maps, then fogs them (sky light only, 150 m
visibility) with `mr fog <folder> -j 2` and with libmr.dask.fog_frames on a LocalCluster of 2
worker processes x 1 thread (the cluster started before timing; its start-up is printed apart).
Prints wall time and photos per second of each. Every output is written (no skips: fresh
output folders).
"""

import argparse
import contextlib
import pathlib
import shutil
import subprocess
import time

import numpy as np

import libmr
import libmr.dask


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mr")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--scratch", default="/tmp/libmr_dask_bench")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--trim", action="store_true",
                    help="keep distributed's default MALLOC_TRIM_THRESHOLD_ in the workers")
    ap.add_argument("--threads-per-worker", type=int, default=1)
    a = ap.parse_args()
    scratch = pathlib.Path(a.scratch)
    shutil.rmtree(scratch, ignore_errors=True)
    frames = scratch / "frames"
    frames.mkdir(parents=True)
    h, w = a.height, a.width
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    rng = np.random.default_rng(2)
    for i in range(a.frames):
        photo = np.stack([(xs + 7 * i) % w / w, ys / h, np.full_like(xs, 0.35)], -1)
        photo = np.clip(photo + rng.normal(0, 0.02, photo.shape), 0, 1).astype(np.float32)
        depth = np.where(ys < 0.3 * h, np.inf, 2.0 + 400.0 / (1.0 + np.maximum(ys - 0.3 * h, 0))).astype(np.float32)
        libmr.write_image(frames / f"f{i:04d}.jpg", photo)
        libmr.write_image(frames / f"f{i:04d}_depth.exr", depth, pixel_type="float")
    print(f"{a.frames} frames of {w}x{h} ({w * h / 1e6:.1f} MP)")

    t0 = time.perf_counter()
    subprocess.run([a.mr, "fog", str(frames), "--out-dir", str(scratch / "mr"), "-j", "2", "-q"],
                   check=True)
    mr_s = time.perf_counter() - t0
    print(f"mr fog -j 2:                  {mr_s:7.2f} s  {a.frames / mr_s:6.2f} photos/s")

    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    environment = libmr.dask.local_worker_environment() if not a.trim else contextlib.nullcontext()
    with environment:
        cluster = LocalCluster(n_workers=a.workers, threads_per_worker=a.threads_per_worker,
                               processes=True, dashboard_address=None)
    client = Client(cluster)
    client.run(lambda: __import__("libmr").version())  # workers import libmr before timing
    start_s = time.perf_counter() - t0
    scene = libmr.Scene()
    scene.medium.sigma_t_per_m = (libmr.extinction_from_visibility(150.0),) * 3
    try:
        t0 = time.perf_counter()
        summary = libmr.dask.fog_frames(frames, scratch / "dask", scene=scene, scheduler=client)
        dask_s = time.perf_counter() - t0
    finally:
        client.close()
        cluster.close()
    assert summary.done == a.frames, str(summary)
    print(f"libmr.dask, {a.workers} workers x {a.threads_per_worker}:    {dask_s:7.2f} s  {a.frames / dask_s:6.2f} photos/s"
          f"  (cluster start-up {start_s:.1f} s apart)")
    print(f"dask / mr throughput: {mr_s / dask_s:.2f}x")


if __name__ == "__main__":
    main()
