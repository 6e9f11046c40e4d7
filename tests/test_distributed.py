"""Bakes on a Dask cluster (distributed.py): identical to a local bake whatever the workers do,
a dead worker's units run again, a failing unit and an unreachable scheduler said plainly.
One LocalCluster of two worker processes serves the whole module."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")

from conftest import CORNELL, ROOT  # noqa: E402
from detp_bake.lightmap import texels as texels_mod  # noqa: E402
from detp_bake.run.bake import BakeSettings, Progress, TraceJob, compute  # noqa: E402
from detp_bake.cli import main  # noqa: E402
from detp_bake.run.distributed import Cluster  # noqa: E402
from detp_bake.errors import BakeError  # noqa: E402
from detp_bake.estimators import Context, EstimatorSettings  # noqa: E402
from detp_bake.scene import PointLight  # noqa: E402
from synthetic import make_scene, uv_sphere  # noqa: E402


@pytest.fixture(scope="module")
def cluster():
    with Cluster(workers=2) as c:
        yield c


def _sphere():
    return make_scene([("Sphere", uv_sphere(1.0, 24, 48, inward=True), 0.5, True)],
                      [PointLight("Lamp", np.zeros(3), np.full(3, 100.0))], resolution=32)


def _settings(name, photons=200_000, **kw):
    return BakeSettings(estimator=name, photons=photons, bounces=3, batch_size=20_000, denoise=False,
                        estimator_settings=EstimatorSettings(radius=0.1), **kw)


def _same(a, b):
    assert np.array_equal(a.value, b.value)
    for name in a.images:
        assert np.array_equal(a.images[name], b.images[name])
    ra, rb = a.report(), b.report()
    for key in ("photons", "segments", "hits", "flux", "noise"):
        assert ra[key] == rb[key], key


def test_a_local_bake_imports_no_dask():
    code = ("import sys, detp_bake.run.bake, detp_bake.cli, detp_bake.run.distributed, detp_bake.estimators as e; "
            "e.names(); bad = [m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')]; "
            "assert not bad, bad")
    proc = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(ROOT)),
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("name", ["disc_index", "sphere_cache", "photon_map"])
def test_two_workers_bake_exactly_what_one_process_bakes(cluster, name):
    sc = _sphere()
    # Light probes (disc_index's case): gathered here from the lightmaps the cluster's photons made.
    probes = {"probes": "auto", "probe_spacing": 0.5, "probe_rays": 32} if name == "disc_index" else {}
    local = compute(sc, _settings(name, **probes))
    far = compute(sc, _settings(name, **probes), cluster=cluster)
    _same(local, far)
    assert len(local.probes) == len(far.probes) == (1 if probes else 0)
    for a, b in zip(local.probes, far.probes):
        assert len(a) > 0 and np.array_equal(a.coefficients, b.coefficients)
    assert far.cluster["workers"] == 2 and far.cluster["units"] >= 3 and far.cluster["resubmitted"] == 0
    assert "cluster" in far.report() and "cluster" not in local.report()


def test_a_noise_target_stops_at_the_same_batch_as_here(cluster):
    sc = _sphere()
    settings = BakeSettings(estimator="disc_index", photons=2_000_000, bounces=3, batch_size=20_000, denoise=False,
                            target_noise=4.0, estimator_settings=EstimatorSettings(radius=0.1))
    local = compute(sc, settings)
    far = compute(sc, settings, cluster=cluster)
    assert local.stopped_by == far.stopped_by == "target_noise" and local.share < 0.2
    assert local.share == far.share
    _same(local, far)


def test_a_killed_worker_loses_only_its_units(cluster):
    """SIGKILL to the worker that just took a unit: the scheduler runs the unit again elsewhere,
    the lightmap is the same bit for bit and the report counts the unit."""
    sc, settings = _sphere(), _settings("disc_index", 400_000)
    local = compute(sc, settings)
    client = cluster.client
    pids = client.run(os.getpid)
    killed = []

    def progress(p: Progress):
        if p.phase == "trace" and not killed:
            busy = {a: max(int(k.rsplit("-", 1)[1]) for k in keys) for a, keys in client.processing().items() if keys}
            if busy:
                victim = max(busy, key=busy.get)
                os.kill(pids[victim], signal.SIGKILL)
                killed.append(victim)
    far = compute(sc, settings, progress, cluster=cluster)
    assert killed
    _same(local, far)
    assert far.cluster["resubmitted"] >= 1
    client.wait_for_workers(2, timeout=60)  # the nanny starts a new one: the module goes on with two


def test_a_failing_unit_stops_the_bake_with_the_workers_message(cluster):
    sc = _sphere()
    job = TraceJob(sc, texels_mod.rasterise(sc), _settings("disc_index"), ["no_such_estimator"], 1, 20_000, 0.0,
                   Context())
    with pytest.raises(BakeError, match=r"batch [01]\) failed on worker tcp://.*unknown estimator 'no_such_estimator'"):
        list(cluster.partials(job, [range(0, 1), range(1, 2)], lambda: False, lambda n: None, (0, 0)))


def test_an_unreachable_scheduler_fails_fast_naming_the_address(capsys, tmp_path):
    code = main(["bake", str(CORNELL), "--out", str(tmp_path), "--scheduler", "tcp://127.0.0.1:9",
                 "--connect-timeout", "1"])
    err = capsys.readouterr().err  # the message says the 1 s limit was what ended it (the wait is not timed here)
    assert code == 2 and "could not reach the scheduler at tcp://127.0.0.1:9 within 1 s" in err, err
    assert not list(tmp_path.iterdir())


def test_the_cli_through_a_scheduler_writes_the_same_files(cluster, tmp_path, bpy):
    args = ["bake", str(CORNELL), "--objects", "Floor", "TallBox", "--photons", "60000", "--resolution", "16",
            "--no-denoise"]
    assert main(args + ["--out", str(tmp_path / "here")]) == 0
    assert main(args + ["--out", str(tmp_path / "far"), "--scheduler", cluster.address]) == 0
    for name in ("Floor.texel_histogram.exr", "TallBox.texel_histogram.exr"):
        assert (tmp_path / "here" / name).read_bytes() == (tmp_path / "far" / name).read_bytes()
    report = json.loads((tmp_path / "far" / "report.json").read_text())
    assert report["cluster"]["workers"] == 2 and report["cluster"]["address"] == cluster.address


def test_the_preferences_button_reports_the_workers_and_their_cores(cluster, bpy, capfd, monkeypatch):
    from test_addon import PACKAGE, _import_addon
    module = _import_addon()
    module.register()
    entry = bpy.context.preferences.addons.new()
    entry.module = PACKAGE
    try:
        prefs = bpy.context.preferences.addons[PACKAGE].preferences
        prefs.scheduler_address = cluster.address
        capfd.readouterr()
        assert bpy.ops.detp_bake.test_cluster() == {"FINISHED"}
        said = capfd.readouterr()
        assert f"{cluster.address}: 2 workers, 2 cores" in said.out + said.err, said
        prefs.scheduler_address = "tcp://127.0.0.1:9"
        monkeypatch.setattr(sys.modules["detp_bake.options"], "CONNECT_TIMEOUT", 1.0)
        with pytest.raises(RuntimeError, match="could not reach the scheduler at tcp://127.0.0.1:9"):
            bpy.ops.detp_bake.test_cluster()
        if not bpy.app.online_access:  # another machine is the network: Blender's Allow Online Access first
            prefs.scheduler_address = "tcp://10.0.0.5:8786"
            with pytest.raises(RuntimeError, match="tcp://10.0.0.5:8786 of the preferences needs Allow Online Access"):
                bpy.ops.detp_bake.test_cluster()
    finally:
        bpy.context.preferences.addons.remove(entry)
        module.unregister()


def test_cancel_cancels_the_units_still_out_and_writes_nothing(cluster, tmp_path):
    from detp_bake.run.bake import bake
    from detp_bake.errors import BakeCancelled
    import threading
    cancel = threading.Event()

    def progress(p: Progress):
        if p.phase == "trace":
            cancel.set()
    with pytest.raises(BakeCancelled):
        bake(_sphere(), _settings("disc_index", 400_000), tmp_path, progress, cancel, cluster=cluster)
    assert not list(tmp_path.iterdir())
    left = None
    for _ in range(50):
        left = cluster.client.run_on_scheduler(
            lambda dask_scheduler=None: [k for k, t in dask_scheduler.tasks.items()
                                         if "detp_bake-unit" in str(k) and t.state in ("processing", "queued", "no-worker")])
        if not left:
            break
        time.sleep(0.1)
    assert not left


def test_units_are_sized_by_the_workers_memory_limit(cluster):
    limit = cluster.describe()["memory_limit"]
    blocks = [range(b, b + 1) for b in range(60)]
    assert [len(u) for u in cluster._units(blocks, (0, 1))] == [10] * 6  # three per worker thread
    per_block = int(0.1 * limit)
    units = cluster._units(blocks, (int(0.6 * limit) - int(2.5 * per_block), per_block))
    assert max(len(u) for u in units) == 2 and sum(len(u) for u in units) == 60
    with pytest.raises(BakeError, match=r"memory limit of worker tcp://"):
        cluster._units(blocks, (int(0.6 * limit), per_block))


def test_the_core_uploaded_to_a_worker_imports_without_blender(tmp_path):
    from detp_bake.run.distributed import core_bootstrap
    source, digest = core_bootstrap()
    (tmp_path / "boot.py").write_text(source)
    code = ("import sys, boot, detp_bake.run.distributed, detp_bake.run.bake, os; "
            "assert detp_bake.__file__.startswith(boot._HOME), detp_bake.__file__; "
            "assert not os.path.exists(os.path.join(boot._HOME, 'detp_bake', 'blender')); "
            "assert 'bpy' not in sys.modules")
    env = dict(os.environ, PYTHONPATH=str(tmp_path), TMPDIR=str(tmp_path))
    proc = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / f"detp_bake_core_{digest}" / "detp_bake" / "transport" / "photons.py").is_file()


def test_classes_travel_by_their_core_name_from_blenders_package_path(monkeypatch):
    """In Blender the core is bl_ext.<repo>.detp_bake.detp_bake: what the client pickles must
    name detp_bake.… for workers that have the core alone."""
    import pickle
    from detp_bake.run import distributed
    from detp_bake import scene
    prefix = "bl_ext.user_default.detp_bake.detp_bake"
    monkeypatch.setattr(distributed, "_PREFIX", prefix)
    stand_in = type("BakeObject", (), {"__module__": prefix + ".scene"})

    def run_unit():
        pass
    run_unit.__module__, run_unit.__qualname__ = prefix + ".run.distributed", "run_unit"
    data = distributed._dumps({"object": stand_in, "function": run_unit, "run": distributed._by_name(run_unit)})
    assert b"bl_ext" not in data
    back = pickle.loads(data)
    assert back["object"] is scene.BakeObject
    assert back["function"] is distributed.run_unit and back["run"] is distributed.run_unit


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _busy_worker(address: str, names: set, bake, seconds: float = 120.0):
    """The name of a worker among `names` that the scheduler shows processing units while `bake`
    (a process) runs; None when the bake ends first."""
    from distributed import Client
    with Client(address) as watcher:
        end = time.monotonic() + seconds
        while time.monotonic() < end and bake.poll() is None:
            workers = watcher.scheduler_info(n_workers=-1)["workers"]
            for addr, keys in watcher.processing().items():
                name = str(workers.get(addr, {}).get("name"))
                if keys and name in names:
                    return name
            time.sleep(0.01)
    return None


def _descendants(pid: int) -> set:
    """`pid` and every process below it (/proc's parent ids)."""
    parents = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rpartition(")")[2].split()
        except OSError:
            continue  # gone meanwhile
        parents[int(stat.parent.name)] = int(fields[1])
    found, grew = {pid}, True
    while grew:
        more = {p for p, parent in parents.items() if parent in found} - found
        found |= more
        grew = bool(more)
    return found


def _listening(pids: set) -> list:
    """(hex address, port) of each listening TCP socket the processes `pids` hold (/proc/net/tcp, tcp6)."""
    inodes = set()
    for pid in pids:
        for fd in Path(f"/proc/{pid}/fd").glob("*"):
            try:
                link = os.readlink(fd)
            except OSError:
                continue
            if link.startswith("socket:["):
                inodes.add(link[8:-1])
    out = []
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] == "0A" and fields[9] in inodes:  # 0A: LISTEN
                address, port = fields[1].split(":")
                out.append((address, int(port, 16)))
    return out


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="reads the listening sockets off Linux's /proc")
def test_a_local_cluster_listens_on_loopback_only(cluster):
    """--workers starts a LocalCluster: its scheduler, nannies, workers and the scheduler's HTTP
    endpoint take connections from this machine only."""
    sockets = _listening(_descendants(os.getpid()))
    loopback = ("0100007F", "00000000000000000000000001000000")  # 127.0.0.1, ::1 as /proc writes them
    assert len(sockets) >= 5, sockets  # the scheduler and its HTTP endpoint, two nannies, two workers
    assert [s for s in sockets if s[0] not in loopback] == [], sockets


@pytest.mark.parametrize("second", ["before", "during"])
def test_a_scheduler_and_workers_of_their_own_survive_a_killed_worker(tmp_path, bpy, second):
    """`dask scheduler` and two `dask worker` processes started apart, the bake through the CLI's
    --scheduler: one worker is killed (SIGKILL) while units run; the files are byte-identical to a
    bake here, and report.json counts the units that ran again. `during`: the second worker joins
    only once tracing runs, so the killed one held the only copy of the bake, and the scheduler
    drops the units that needed it (they are sent again, with the bake)."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", str(port), "--no-dashboard"], **quiet)]
    try:
        def worker(k):
            procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                           "--nthreads", "1", "--no-nanny", "--no-dashboard", "--name", f"w{k}"],
                                          **quiet))
        worker(0)
        if second == "before":
            worker(1)
            from distributed import Client
            with Client(address) as watcher:  # both are in before the bake starts (a loaded machine is slow)
                watcher.wait_for_workers(2)
        args = [sys.executable, "-m", "detp_bake", "bake", str(CORNELL), "--objects", "Floor", "TallBox",
                "--photons", "2000000" if second == "before" else "8000000", "--resolution", "16", "--no-denoise",
                "--connect-timeout", "60"]
        here = subprocess.run(args + ["--out", str(tmp_path / "here")], env=env, capture_output=True, text=True)
        assert here.returncode == 0, here.stderr
        far = subprocess.Popen(args + ["--out", str(tmp_path / "far"), "--scheduler", address], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        err, killed = [], None
        for line in far.stderr:  # the first traced units are in: the others are running
            err.append(line)
            if "Tracing" in line:
                if second == "during":
                    worker(1)
                    from distributed import Client
                    with Client(address) as watcher:  # the second has joined before the first goes
                        watcher.wait_for_workers(2)
                # The one killed holds units at that moment (the scheduler says which): a worker
                # between units would lose nothing, and nothing would run again.
                busy = _busy_worker(address, {"w0", "w1"} if second == "before" else {"w0"}, far)
                if busy is None:
                    far.kill()
                    pytest.skip("the bake ended before the scheduler showed a worker holding a unit")
                killed = procs[1 + int(busy[1])]
                killed.send_signal(signal.SIGKILL)
                assert far.poll() is None  # units were still out when it died
                break
        rest, more = far.communicate(timeout=300)
        assert far.returncode == 0, "".join(err) + more
        assert killed is not None and killed.wait(timeout=10) == -signal.SIGKILL
        for name in ("Floor.texel_histogram.exr", "TallBox.texel_histogram.exr"):
            assert (tmp_path / "here" / name).read_bytes() == (tmp_path / "far" / name).read_bytes()
        report = json.loads((tmp_path / "far" / "report.json").read_text())
        assert report["cluster"]["address"] == address and report["cluster"]["resubmitted"] >= 1, report["cluster"]
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
                p.wait(timeout=30)


def test_a_frame_range_on_the_cluster_writes_what_a_range_here_writes(cluster, tmp_path):
    """A frame range (the hybrid over the quasi-static scene of test_hybrid) with its photons traced
    on the workers: every frame's lightmaps are the same bytes as a range baked here."""
    from detp_bake.run import frames
    from test_frames import _settings
    from test_hybrid import scene_at
    here = frames.bake_frames(lambda f: scene_at(f - 1), frames.parse_frames("1-2"), _settings(), tmp_path / "here")
    far = frames.bake_frames(lambda f: scene_at(f - 1), frames.parse_frames("1-2"), _settings(), tmp_path / "far",
                             cluster=cluster)
    assert here.frames == far.frames == [1, 2]
    for frame in (1, 2):
        for name, paths in here.files[frame].items():
            for mine, theirs in zip(paths, far.files[frame][name]):
                assert open(mine, "rb").read() == open(theirs, "rb").read(), (frame, name)
    assert all(section["cluster"]["workers"] == 2 for section in far.sections)
    assert not any("cluster" in section for section in here.sections)


def test_an_atlas_bakes_on_the_cluster_as_here(cluster):
    from test_atlas import _two_plates_in_one_atlas
    sc = _two_plates_in_one_atlas(gap_texels=3)
    settings = BakeSettings(photons=60_000, batch_size=20_000, seed=4)
    _same(compute(sc, settings), compute(sc, settings, cluster=cluster))
