"""Fog a folder or a list of frames on a Dask cluster, with the guarantees of `mr fog`.

    import libmr, libmr.dask
    scene = libmr.load_scene("fog.json")
    summary = libmr.dask.fog_frames("frames/", "foggy/", scene=scene)              # LocalCluster
    summary = libmr.dask.fog_frames(paths, "foggy/", scene=scene, scheduler="tcp://head:8786")
    print(summary)            # done / skipped / failed, and each failure's one-line reason

Each frame is a task, libmr.fog_file: exactly what `mr fog` does with one photo (sky-light-only
scenes stream through decode -> fog -> encode in strips, others render the whole frame; the GIL
released), the output written atomically (a hidden temporary file renamed into place: a reader
never sees a partial file, a killed worker leaves no partial output). Outputs that exist are skipped
(unless overwrite=True), so a killed run resumes where it stopped; a worker that dies mid-task
has its task re-run elsewhere by Dask. A bad frame (unreadable, corrupt, missing or wrong-size
depth) is reported in the summary and the batch goes on. Outputs are named as by `mr fog`:
<out_dir>/<stem><suffix>.<ext>, and tagged with its Software tag, so `mr fog` resumes a batch
this module began and vice versa. Progress: Dask's own diagnostics (the dashboard of the cluster,
`summary.dashboard_link`), and a line per `progress_every` frames when `progress` is true.

Requires Debian's python3-dask and python3-distributed (scripts/setup installs them).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import os
import pathlib
import re
import sys
import time
import uuid
from typing import Callable, Iterable, List, Optional, Sequence, Tuple, Union

import libmr

PathLike = Union[str, os.PathLike]

# What `mr fog` looks for and writes (README, `mr fog`).
DEPTH_EXTENSIONS = (".exr", ".tif", ".tiff", ".pfm", ".png")
NOT_PHOTOS = re.compile(r".*_(depth|disparity|aovs)$")
OUTPUT_SOFTWARE = "mr fog (libmr)"
_TEMPORARY = re.compile(r"^\..+\.mr-tmp-([0-9]{1,9})-[0-9]+(\.[A-Za-z0-9]+)?$")
_A_DAY_S = 24 * 3600


@dataclasses.dataclass
class Frame:
    """One frame of a batch: its photo, depth map and output."""

    photo: str
    depth: str
    output: str


@dataclasses.dataclass
class Summary:
    """What a batch did. `failed` holds (photo, one-line reason) per bad frame."""

    done: int = 0
    skipped: int = 0
    failed: List[Tuple[str, str]] = dataclasses.field(default_factory=list)
    elapsed_s: float = 0.0
    dashboard_link: Optional[str] = None
    removed_temporaries: List[str] = dataclasses.field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failed

    def __str__(self) -> str:
        lines = [f"{self.done} done, {self.skipped} skipped, {len(self.failed)} failed "
                 f"in {self.elapsed_s:.1f} s"]
        lines += [f"  FAILED {photo}: {reason}" for photo, reason in self.failed]
        return "\n".join(lines)


def find_depth(photo: PathLike, pattern: Optional[str] = None) -> Optional[str]:
    """The depth map of a photo: `pattern` with {dir} {stem} {name} {ext} (or one file for all);
    by default {dir}/{stem}_depth.{exr,tif,tiff,pfm,png}, the first that exists."""
    p = pathlib.Path(photo)
    fields = {"dir": str(p.parent), "stem": p.stem, "name": p.name, "ext": p.suffix.lstrip(".")}
    if pattern:
        return pattern.format(**fields)
    for ext in DEPTH_EXTENSIONS:
        candidate = p.parent / f"{p.stem}_depth{ext}"
        if candidate.exists():
            return str(candidate)
    return None


def list_frames(inputs: Union[PathLike, Iterable[PathLike]]) -> List[str]:
    """Photos from a folder (its image files, not recursive, without *_depth / *_disparity /
    *_aovs and hidden files) or from an iterable of paths (taken as given)."""
    if isinstance(inputs, (str, os.PathLike)) and pathlib.Path(inputs).is_dir():
        folder = pathlib.Path(inputs)
        return sorted(
            str(p) for p in folder.iterdir()
            if not p.name.startswith(".") and libmr.is_readable_image_extension(p)
            and not NOT_PHOTOS.match(p.stem) and (p.is_file() or not p.exists())
        )
    if isinstance(inputs, (str, os.PathLike)):
        return [str(inputs)]
    return [str(p) for p in inputs]


def plan_frames(photos: Sequence[str], out_dir: PathLike, depth: Optional[str] = None,
                suffix: str = "_fog", format: Optional[str] = None
                ) -> Tuple[List[Frame], List[Tuple[str, str]]]:
    """Frames to fog and the photos that fail before anything renders (as `mr fog`: no depth
    map, an output that is an input, two photos writing one output)."""
    out_dir = pathlib.Path(out_dir)
    frames: List[Frame] = []
    failed: List[Tuple[str, str]] = []
    inputs = set()
    planned = []
    for photo in photos:
        d = find_depth(photo, depth)
        ext = (format or pathlib.Path(photo).suffix.lstrip(".")).lstrip(".")
        output = str(out_dir / f"{pathlib.Path(photo).stem}{suffix}.{ext}")
        planned.append((photo, d, output))
        inputs.add(os.path.abspath(photo))
        if d:
            inputs.add(os.path.abspath(d))
    by_output = {}
    for photo, d, output in planned:
        by_output.setdefault(os.path.abspath(output), []).append(photo)
    for photo, d, output in planned:
        sharing = by_output[os.path.abspath(output)]
        if d is None:
            failed.append((photo, f"no depth map found ({pathlib.Path(photo).stem}_depth"
                                  f"{{{','.join(e.lstrip('.') for e in DEPTH_EXTENSIONS)}}})"))
        elif os.path.abspath(output) in inputs:
            failed.append((photo, f"output {output} is an input of this run; refusing to overwrite it"))
        elif len(sharing) > 1:
            other = next(p for p in sharing if p != photo)
            failed.append((photo, f"output {output} would also be written for {other}"))
        else:
            frames.append(Frame(photo, d, output))
    return frames, failed


def fog_frame(frame: Frame, scene_json: str, overwrite: bool = False,
              pixel_type: str = "automatic") -> Tuple[str, str, str]:
    """Fogs one frame (runs on a worker). Returns (status, photo, reason): status 'done',
    'skipped' (its output exists) or 'failed' (reason: the one-line error)."""
    if not overwrite and os.path.exists(frame.output):
        return ("skipped", frame.photo, "")
    try:
        scene = libmr.scene_from_json(scene_json, "scene")
        # As `mr fog`: sky-only scenes stream in strips, others render the whole frame; the
        # output is written atomically, tagged as mr fog's.
        libmr.fog_file(frame.photo, frame.depth, frame.output, scene, pixel_type=pixel_type,
                       software=OUTPUT_SOFTWARE, overwrite=True)
        return ("done", frame.photo, "")
    except libmr.Error as e:
        return ("failed", frame.photo, e.message)
    except Exception as e:  # noqa: BLE001 - a batch reports every bad frame and goes on
        return ("failed", frame.photo, f"{type(e).__name__}: {e}")


def remove_stale_temporaries(folder: PathLike, local: bool = True) -> List[str]:
    """Removes the hidden temporaries of atomic writes that a killed worker left in `folder`
    (".<stem>.mr-tmp-<pid>-<n>[.<ext>]"): those older than a day, and, when every writer runs on
    this host (`local`), those whose process is gone. Returns the paths removed."""
    removed = []
    try:
        entries = list(os.scandir(folder))
    except FileNotFoundError:
        return removed
    now = time.time()
    for entry in entries:
        m = _TEMPORARY.match(entry.name)
        if not m or not entry.is_file(follow_symlinks=False):
            continue
        stale = now - entry.stat(follow_symlinks=False).st_mtime > _A_DAY_S
        if not stale and local:
            try:
                os.kill(int(m.group(1)), 0)
            except ProcessLookupError:
                stale = True
            except PermissionError:
                pass
        if stale:
            try:
                os.unlink(entry.path)
                removed.append(entry.path)
            except FileNotFoundError:
                pass
    return removed


def local_worker_environment():
    """A dask config context for starting local workers without the MALLOC_TRIM_THRESHOLD_ that
    distributed sets by default: any fixed glibc trim threshold also fixes the mmap threshold, so
    every frame's large buffers are mmapped afresh and page-faulted in again (libmr's batch path
    reuses them; see README "Batch speed and memory"). The numpy thread limits are kept."""
    import dask

    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return dask.config.set({"distributed.nanny.pre-spawn-environ": environ})


def fog_frames(inputs: Union[PathLike, Iterable[PathLike]], out_dir: PathLike, *,
               scene: Optional["libmr.Scene"] = None, depth: Optional[str] = None,
               suffix: str = "_fog", format: Optional[str] = None, pixel_type: str = "automatic",
               overwrite: bool = False, scheduler=None, n_workers: int = 2,
               threads_per_worker: int = 1, max_in_flight: Optional[int] = None,
               progress: bool = False, progress_every: int = 100,
               log: Callable[[str], None] = lambda line: print(line, file=sys.stderr)) -> Summary:
    """Fogs `inputs` (a folder, one photo, or an iterable of photo paths) into `out_dir` on a
    Dask cluster and returns a Summary.

    scene: a libmr.Scene (None: the defaults, as `mr fog`); sent to the workers as its JSON
    document. depth: a pattern with {dir} {stem} {name} {ext} (default: {dir}/{stem}_depth.{exr,
    tif,tiff,pfm,png}, the first that exists; metres along the ray). suffix / format: output
    names <stem><suffix>.<format or the input's extension>. scheduler: None starts a LocalCluster
    of n_workers processes x threads_per_worker threads (closed at the end); an address
    ('tcp://host:8786') or a distributed.Client uses that cluster. max_in_flight: tasks
    submitted at once (default 4 per worker thread), so millions of frames need no million
    futures."""
    from distributed import Client, LocalCluster, as_completed

    start = time.monotonic()
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    scene_json = libmr.scene_to_json(scene if scene is not None else libmr.Scene())
    frames, failed = plan_frames(list_frames(inputs), out_dir, depth, suffix, format)
    summary = Summary(failed=list(failed))

    own_cluster = None
    if scheduler is None:
        # The dashboard (Dask's progress diagnostics) needs bokeh; without it, none.
        dashboard = ":0" if importlib.util.find_spec("bokeh") else None
        with local_worker_environment():
            own_cluster = LocalCluster(n_workers=n_workers, threads_per_worker=threads_per_worker,
                                       processes=True, dashboard_address=dashboard)
        client = Client(own_cluster)
    elif isinstance(scheduler, Client):
        client = scheduler
    else:
        client = Client(scheduler)
    # Temporaries of dead writers: only where every writer is on this host can a pid be checked.
    local = own_cluster is not None or _is_local_cluster(client)
    try:
        summary.dashboard_link = getattr(client, "dashboard_link", None)
        summary.removed_temporaries += remove_stale_temporaries(out_dir, local)
        if progress and summary.dashboard_link:
            log(f"libmr.dask: {len(frames)} frames; progress on the dashboard {summary.dashboard_link}")
        threads = sum(client.nthreads().values()) or 1
        window = max_in_flight or max(8, 4 * threads)
        todo = iter(enumerate(frames))
        pending = as_completed()
        run_id = uuid.uuid4().hex[:12]
        photo_of_key = {}

        def submit_next() -> bool:
            item = next(todo, None)
            if item is None:
                return False
            i, frame = item
            key = f"libmr-fog-{run_id}-{i}"
            photo_of_key[key] = frame.photo
            pending.add(client.submit(fog_frame, frame, scene_json, overwrite, pixel_type,
                                      key=key, pure=False))
            return True

        for _ in range(window):
            if not submit_next():
                break
        finished = 0
        for future in pending:
            try:
                status, photo, reason = future.result()
            except Exception as e:  # noqa: BLE001 - e.g. KilledWorker: the task killed workers
                status, photo, reason = "failed", photo_of_key[future.key], f"{type(e).__name__}: {e}"
            finally:
                photo_of_key.pop(future.key, None)
                future.release()
            if status == "done":
                summary.done += 1
            elif status == "skipped":
                summary.skipped += 1
            else:
                summary.failed.append((photo, reason))
            finished += 1
            if progress and finished % max(1, progress_every) == 0:
                log(f"libmr.dask: {finished}/{len(frames)} frames ({summary.done} done, "
                    f"{summary.skipped} skipped, {len(summary.failed)} failed)")
            submit_next()
        summary.removed_temporaries += remove_stale_temporaries(out_dir, local)
    finally:
        if own_cluster is not None:
            client.close()
            own_cluster.close()
        elif not isinstance(scheduler, Client):
            client.close()
    summary.elapsed_s = time.monotonic() - start
    if progress:
        log(f"libmr.dask: {summary}")
    return summary


def _is_local_cluster(client) -> bool:
    try:
        hosts = {addr.split("://")[-1].rsplit(":", 1)[0] for addr in client.nthreads()}
        return hosts <= {"127.0.0.1", "localhost", "::1", "[::1]"}
    except Exception:  # noqa: BLE001
        return False
