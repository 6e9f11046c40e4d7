"""Bakes on a Dask cluster: the photon batches traced on workers, summed here in batch order.

A bake's batches fall into blocks (batches.blocks), each estimated from zero; a unit is a run of
blocks, and a worker returns each block's sums (bake.trace_batches, the very function the local
bake runs). The client adds them in batch order (bake.Totals), so the lightmaps are identical bit
for bit to a local bake with the same seed, whatever the number of workers, the order units finish
in, or a worker dying halfway (the scheduler runs its units again elsewhere).

What crosses the wire is plain: the bake's inputs (bake.TraceJob, pickled once and scattered to
every worker), which a worker unpacks once and keeps with the tracer and the estimators it builds
from them (the disc index); and back, dicts of numpy arrays and numbers. Classes travel by their
name in the core (`detp_bake.…`) whatever the client's import path (Blender's `bl_ext.…`), so a
worker needs the core and its dependencies (numpy, embreex, numba) and no Blender: either
`detp_bake` importable there (PYTHONPATH), or the client uploads its own copy (`upload_core`).

Dask is imported only here, and only when a Cluster connects.
"""
from __future__ import annotations

import base64
import hashlib
import io
import os
import pickle
import pydoc
import threading
import time
import types
import uuid
import zipfile
from concurrent.futures import CancelledError
from pathlib import Path
from typing import Callable, Iterator, Optional

from .. import __version__
from ..errors import BakeCancelled, BakeError
from ..options import CONNECT_TIMEOUT  # seconds to reach the scheduler and see a worker
from . import bake

UNITS_PER_SLOT = 3  # units per worker thread: small enough to balance, large enough to amortise
MAX_UNIT_BATCHES = 16  # batches in a unit: a few seconds of one core
EARLY_STOP_UNIT_BATCHES = 4  # for bakes that may stop early (noise target, time limit): little traced in vain
AHEAD_PER_SLOT = 2  # units submitted ahead of the one the client adds next, per worker thread
RESEND = 3  # times a unit the scheduler dropped (its worker died with the bake's only copy) is sent again
MEMORY_SHARE = 0.6  # of a worker's memory limit a unit may plan to use
CORE = "detp_bake"  # the core's package name on the workers
LOCAL_HOST = "127.0.0.1"  # what a local cluster (--workers) listens on
_PREFIX = __name__.rsplit(".", 2)[0]  # the core's package name here ("detp_bake" or bl_ext.….detp_bake): run/'s parent


class Cluster:
    """A connection to a Dask scheduler (`scheduler`, e.g. tcp://10.0.0.5:8786) or a LocalCluster
    of `workers` processes on this machine. Use as a context manager; pass it to bake.compute."""

    def __init__(self, scheduler: str = "", workers: int = 0, timeout: float = CONNECT_TIMEOUT,
                 upload: Optional[bool] = None):
        if bool(scheduler) == bool(workers):
            raise BakeError("a cluster needs a scheduler address or a number of local workers (one of them)")
        if workers and workers < 1:
            raise BakeError(f"setting 'workers' = {workers!r}: must be 1 or more")
        self.scheduler, self.workers, self.timeout = scheduler, int(workers), float(timeout)
        self.upload = upload  # None: upload the core where a worker lacks it or has another version
        self.client = None
        self.local = None
        self.last: dict = {}  # what the last bake did on the cluster (report.json's "cluster")

    def __enter__(self) -> "Cluster":
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def address(self) -> str:
        return self.scheduler or (self.local.scheduler_address if self.local is not None else "a local cluster")

    def connect(self) -> None:
        """Reach the scheduler (or start the local cluster) and wait for a worker: BakeError naming
        the address when that takes longer than `timeout`."""
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise BakeError("distributed bakes need the dask and distributed packages "
                            "(pip install dask distributed)") from None
        try:
            if self.scheduler:
                self.client = Client(self.scheduler, timeout=self.timeout, set_as_default=False)
            else:
                # Loopback only, every port (scheduler, nannies, workers, the scheduler's HTTP
                # endpoint on any free port): workers on this machine need no network.
                self.local = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                          host=LOCAL_HOST, dashboard_address=f"{LOCAL_HOST}:0",
                                          worker_dashboard_address=None)
                self.client = Client(self.local, timeout=self.timeout, set_as_default=False)
            self.client.wait_for_workers(1, timeout=self.timeout)
        except (OSError, TimeoutError) as exc:
            self.close()
            what = "no worker joined the scheduler" if "worker" in str(exc).lower() else "could not reach the scheduler"
            raise BakeError(f"{what} at {self.scheduler or 'the local cluster'} within {self.timeout:g} s "
                            f"({type(exc).__name__}: {exc})") from None
        if self.upload or (self.upload is None and self._workers_lack_core()):
            self.upload_core()

    def close(self) -> None:
        for thing in (self.client, self.local):
            if thing is not None:
                try:
                    thing.close()
                except Exception:  # already gone: nothing to release
                    pass
        self.client = self.local = None

    def describe(self) -> dict:
        """{address, workers, cores, memory_limit (the smallest, bytes; 0: none)}."""
        workers = self.client.scheduler_info(n_workers=-1)["workers"]
        limits = [w.get("memory_limit") or 0 for w in workers.values()]
        return {"address": self.address, "workers": len(workers),
                "cores": sum(w.get("nthreads", 1) for w in workers.values()),
                "memory_limit": min((m for m in limits if m), default=0)}

    def _workers_lack_core(self) -> bool:
        versions = self.client.run(pydoc.locate, f"{CORE}.__version__")
        return any(v != __version__ for v in versions.values())

    def upload_core(self) -> None:
        """Send this client's core to every worker (and to workers that join later): a module that,
        imported there, unpacks the core once per version into the temporary folder, as real files
        (numba caches compiled kernels beside them), and puts it first on sys.path."""
        source, digest = core_bootstrap()
        folder = Path(os.environ.get("TMPDIR", "/tmp")) / f"detp_bake_upload_{uuid.uuid4().hex}"
        folder.mkdir(parents=True)
        path = folder / f"detp_bake_core_{digest}.py"
        path.write_text(source)
        try:
            self.client.upload_file(str(path), load=True)
        finally:
            path.unlink(missing_ok=True)
            folder.rmdir()

    def partials(self, job, blocks: list, cancelled: Callable[[], bool], progress: Callable[[int], None],
                 worker_bytes: tuple[int, int]) -> Iterator:
        """Trace `blocks` (lists of batch numbers) of bake.TraceJob `job` on the workers; yield each
        block's bake.Partial in batch order. Closing the iterator cancels what is still out."""
        client = self.client
        token = uuid.uuid4().hex[:12]
        units = self._units(blocks, worker_bytes, bool(job.settings.target_noise or job.settings.time_limit))
        info = client.scheduler_info(n_workers=-1)["workers"]
        slots = {}
        for address, w in info.items():
            host = _host(address)
            slots[host] = slots.get(host, 0) + w.get("nthreads", 1)
        data = _dumps(job)
        payloads = client.scatter([data], broadcast=True, hash=False)
        run = _by_name(run_unit)
        ahead = AHEAD_PER_SLOT * sum(slots.values())  # units out at once: an early stop wastes little
        news = threading.Event()
        again = {}  # unit -> times it was sent again after the scheduler dropped it

        def submit(i):
            f = client.submit(run, f"job-{token}", payloads[-1], [(b[0], b[-1] + 1) for b in units[i]], slots,
                              job.settings.threads, key=f"detp_bake-unit-{token}-{i}-{again.get(i, 0)}",
                              pure=False, retries=0)
            f.add_done_callback(lambda _: news.set())
            return f
        out, done, nxt, sent, photons, resubmitted = {}, {}, 0, 0, 0, 0
        t0 = time.perf_counter()
        try:
            while nxt < len(units):
                while sent < len(units) and sent - nxt < ahead:
                    out[sent] = submit(sent)
                    sent += 1
                if cancelled():
                    raise BakeCancelled()
                if nxt not in done:
                    news.wait(0.2)
                    news.clear()
                finished = {i: f for i, f in out.items() if f.done()}
                if finished:
                    resubmitted += self._resubmitted([f.key for f in finished.values()])
                for i, f in finished.items():
                    try:
                        if f.status == "cancelled":
                            raise CancelledError(f.key)
                        if f.status != "finished":
                            raise BakeError(_failure(f, units[i]))
                        done[i] = f.result()
                    except CancelledError:  # distributed.FutureCancelledError is one
                        # The scheduler dropped it, before or after it ran: a worker that died held the
                        # only copy of the bake (broadcast reaches the workers there at the time) or of
                        # the result, not gathered yet. Send both again.
                        if again.get(i, 0) >= RESEND:
                            raise BakeError(_failure(f, units[i])) from None
                        again[i] = again.get(i, 0) + 1
                        payloads.extend(client.scatter([data], broadcast=True, hash=False))
                        out[i] = submit(i)
                        resubmitted += 1
                        continue
                    del out[i]  # released: the worker forgets the result
                    photons += sum(p["stats"]["photons"] for p in done[i])
                    progress(photons)
                while nxt in done:
                    for plain in done.pop(nxt):
                        yield bake.Partial.from_plain(plain)
                    nxt += 1
            self.last = {**self.describe(), "units": len(units), "blocks_per_unit": len(units[0]) if units else 0,
                         "resubmitted": resubmitted, "seconds": round(time.perf_counter() - t0, 3)}
        finally:
            client.cancel(list(out.values()), force=True)
            client.cancel(payloads)

    def _units(self, blocks: list, worker_bytes: tuple[int, int], early_stop: bool = False) -> list[list]:
        """Runs of consecutive blocks: about UNITS_PER_SLOT per worker thread (MAX_UNIT_BATCHES at most), fewer
        blocks each where a worker's memory limit (read from the scheduler) would not hold their sums."""
        fixed, per_block = worker_bytes
        workers = self.client.scheduler_info(n_workers=-1)["workers"]
        slots = sum(w.get("nthreads", 1) for w in workers.values()) or 1
        size = max(1, -(-len(blocks) // (UNITS_PER_SLOT * slots)))
        most = EARLY_STOP_UNIT_BATCHES if early_stop else MAX_UNIT_BATCHES
        size = min(size, max(1, most // max(1, len(blocks[0]) if blocks else 1)))
        limited = [(w.get("memory_limit") or 0, a) for a, w in workers.items() if w.get("memory_limit")]
        if limited:
            limit, address = min(limited)
            room = MEMORY_SHARE * limit - fixed
            if room < per_block:
                raise BakeError(f"a worker would need about {(fixed + per_block) / 1e9:,.2f} GB for this bake, more than "
                                f"{MEMORY_SHARE:.0%} of the memory limit of worker {address} ({limit / 1e9:,.2f} GB): "
                                "give the workers more memory, or bake at a lower resolution")
            size = max(1, min(size, int(room // max(per_block, 1))))
        return [blocks[a:a + size] for a in range(0, len(blocks), size)]

    def _resubmitted(self, keys: list) -> int:
        """Units the scheduler ran again because their worker died (its 'suspicious' count), asked
        while the client still holds them; -1 each where the scheduler will not say."""
        try:
            counts = self.client.run_on_scheduler(
                lambda keys, dask_scheduler=None: [dask_scheduler.tasks[k].suspicious for k in keys
                                                   if k in dask_scheduler.tasks], keys)
        except Exception:  # the scheduler refuses to run code: the count is unknown
            return -len(keys)
        return int(sum(counts))


def _failure(future, unit) -> str:
    first, last = unit[0][0], unit[-1][-1]
    what = f"batch {first}" if first == last else f"batches {first}–{last}"
    if future.status == "error":
        exc = future.exception()
        if type(exc).__name__ == "KilledWorker":
            return f"the workers running {what} died repeatedly (out of memory?): {exc}"
        return f"a unit ({what}) failed {exc}"
    return f"a unit ({what}) was {future.status} by the scheduler"


def _host(address: str) -> str:
    return address.split("://")[-1].rpartition(":")[0]


# ---------------------------------------------------------------------------------------------
# On the workers

_LOCK = threading.Lock()  # one unit at a time per worker process: it uses the threads it is given
_JOBS: dict = {}  # job key -> (tracer, estimators), the newest few bakes
KEEP_JOBS = 2


def run_unit(key: str, payload: bytes, blocks: list, slots: dict, threads: int) -> list[dict]:
    """Trace blocks [(first, stop), …] of the bake `payload` (pickled bake.TraceJob) and return each
    block's Partial as plain data. Threads: `threads`, or this host's cores shared between its
    worker threads (`slots`, per host). Any exception comes back as RuntimeError with its message,
    naming this worker."""
    import numba
    address = ""
    try:
        from distributed import get_worker
        address = get_worker().address
    except (ImportError, ValueError):
        pass
    try:
        with _LOCK:
            use = threads or max(1, (os.cpu_count() or 1) // max(1, slots.get(_host(address), 1)))
            before = numba.get_num_threads()
            numba.set_num_threads(max(1, min(use, numba.config.NUMBA_NUM_THREADS)))
            try:
                tracer, runs = _state(key, payload, use)
                return [bake.trace_batches(tracer, runs, range(a, b)).plain() for a, b in blocks]
            finally:
                numba.set_num_threads(before)
    except Exception as exc:
        _JOBS.pop(key, None)  # its estimators may hold half a block
        raise RuntimeError(f"on worker {address or os.getpid()}: {type(exc).__name__}: {exc}") from None


def _state(key: str, payload: bytes, threads: int):
    if key not in _JOBS:
        while len(_JOBS) >= KEEP_JOBS:
            _JOBS.pop(next(iter(_JOBS)))
        job = pickle.loads(payload)
        _JOBS[key] = (job.tracer(threads), job.estimators())
    return _JOBS[key]


# ---------------------------------------------------------------------------------------------
# Plain data across import paths

class _CorePickler(pickle.Pickler):
    """Pickles the core's classes and functions by their name under `detp_bake`, whatever this
    process calls the package (in Blender: bl_ext.<repository>.detp_bake.detp_bake)."""

    def reducer_override(self, obj):
        module = getattr(obj, "__module__", None)
        if isinstance(obj, (type, types.FunctionType)):
            if isinstance(module, str) and (module == _PREFIX or module.startswith(_PREFIX + ".")):
                return pydoc.locate, (CORE + module[len(_PREFIX):] + "." + obj.__qualname__,)
        return NotImplemented


def _dumps(obj) -> bytes:
    if _PREFIX == CORE:
        return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    buf = io.BytesIO()
    _CorePickler(buf, protocol=pickle.HIGHEST_PROTOCOL).dump(obj)
    return buf.getvalue()


class _ByName:
    """A core function sent by its name under `detp_bake` (see _CorePickler)."""

    def __init__(self, name: str):
        self.name = name

    def __call__(self, *args, **kwargs):
        return pydoc.locate(self.name)(*args, **kwargs)

    def __reduce__(self):
        return pydoc.locate, (self.name,)


def _by_name(fn):
    return fn if _PREFIX == CORE else _ByName(f"{CORE}{fn.__module__[len(_PREFIX):]}.{fn.__qualname__}")


def core_zip() -> tuple[bytes, str]:
    """The core as a zip (`detp_bake/…`, without the Blender adapter), and a digest of it."""
    root = Path(__file__).resolve().parents[1]  # the core: this file is run/distributed.py
    buf = io.BytesIO()
    files = sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts and p.relative_to(root).parts[0] != "blender")
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for p in files:
            info = zipfile.ZipInfo(f"{CORE}/{p.relative_to(root).as_posix()}", date_time=(2020, 1, 1, 0, 0, 0))
            z.writestr(info, p.read_bytes(), zipfile.ZIP_DEFLATED)
    data = buf.getvalue()
    return data, hashlib.sha256(data).hexdigest()[:16]


_BOOTSTRAP = '''"""detp_bake's core, uploaded by a client (detp_bake/run/distributed.py): unpacked once per version."""
import base64, io, os, sys, tempfile, uuid, zipfile

_DATA = {data!r}
_HOME = os.path.join(tempfile.gettempdir(), "detp_bake_core_{digest}")
if not os.path.isdir(_HOME):
    _tmp = _HOME + "." + uuid.uuid4().hex
    zipfile.ZipFile(io.BytesIO(base64.b64decode(_DATA))).extractall(_tmp)
    try:
        os.rename(_tmp, _HOME)
    except OSError:  # another worker on this host was first
        import shutil
        shutil.rmtree(_tmp, ignore_errors=True)
if _HOME not in sys.path:
    sys.path.insert(0, _HOME)
for _name in [m for m in sys.modules if m == "{core}" or m.startswith("{core}.")]:
    del sys.modules[_name]  # another version imported before: the next import takes this one
'''


def core_bootstrap() -> tuple[str, str]:
    """(source of the module `upload_core` sends, the core's digest)."""
    data, digest = core_zip()
    return _BOOTSTRAP.format(data=base64.b64encode(data).decode(), digest=digest, core=CORE), digest
