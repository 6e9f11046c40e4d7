"""Writing a bake: every lightmap and report.json staged and put in place together (staging.py),
named <object>.<estimator>[.<frame>].<format>; earlier lightmaps this bake will not replace are
named in a warning, never touched."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Callable, Optional

from .. import __version__
from ..errors import BakeCancelled, BakeError
from ..lightmap import images, staging
from ..probes import grid as probe_grid
from .results import BakeResult, Progress, cancel_fn


def warn_stale(out_dir: Path, result, warn) -> None:
    """One warning listing the lightmaps of the objects being baked, with this estimator, that an
    earlier bake left in `out_dir` and this one will not replace (a PNG from an exr,png bake, a raw
    EXR from a --keep-raw bake). They are left alone, as is every other file there."""
    writing = {p.name for targets in output_paths(result, out_dir).values() for p in targets}
    stale = sorted(name for stem in images.file_stems(result.images).values() for suffix in ("exr", "png", "raw.exr")
                   for name in [f"{stem}.{result.settings.estimator}.{suffix}"]
                   if name not in writing and (out_dir / name).is_file())
    if stale:
        warn(f"{len(stale)} lightmaps in {out_dir} from an older bake of the same objects are left as they "
             f"were (not written this time): {', '.join(stale[:8])}{' …' if len(stale) > 8 else ''}")


def output_paths(result: BakeResult, out_dir: Path, frame: Optional[int] = None) -> dict:
    """<object>.<estimator>.<format>, or <object>.<estimator>.<frame:04d>.<format> for a frame of a
    range (the number last, as image sequences want it)."""
    stems = images.file_stems(result.images)
    number = "" if frame is None else f".{frame:04d}"
    out = {name: [out_dir / f"{stems[name]}.{result.settings.estimator}{number}.{fmt}"
                  for fmt in result.settings.formats] for name in result.images}
    if result.settings.keep_raw and result.raw_images:
        for name, paths in out.items():
            paths.append(out_dir / f"{stems[name]}.{result.settings.estimator}.raw{number}.exr")
    for suffix, _, _ in result.extra_maps():  # last: Apply takes a lightmap's first EXR as its plain lightmap
        for name, paths in out.items():
            paths.append(out_dir / f"{stems[name]}.{result.settings.estimator}.{suffix}{number}.exr")
    return out


def write(result: BakeResult, out_dir: str | os.PathLike,
          progress: Optional[Callable[[Progress], None]] = None, cancel=None,
          frame: Optional[int] = None) -> Optional[Path]:
    """Write every lightmap and report.json; files appear together or not at all. For a `frame` of
    a range the names carry its number and report.json is left to the range (frames.py)."""
    return write_many({result.settings.estimator: result}, out_dir, progress, cancel, frame=frame)


def write_many(results: dict, out_dir: str | os.PathLike, progress: Optional[Callable[[Progress], None]] = None,
               cancel=None, extra: Optional[dict] = None, summary: Optional[dict] = None,
               frame: Optional[int] = None) -> Optional[Path]:
    """Write the lightmaps of one or more results ({estimator: BakeResult}, as `compute_many`
    gives), `extra` files ({file name: write(path)}) and one report.json: a single result's report,
    or (several results, or a `summary` given) `summary` and a section per estimator. Everything is staged under hidden
    temporary names and renamed at the end (staging.py): a cancel, a full disk or any error
    before then leaves the folder as it was. Other files in the folder are left alone."""
    t0 = time.perf_counter()
    cancelled = cancel_fn(cancel)
    out = images.output_folder(out_dir)  # proved writable at the door; a full disk is staging's to handle
    report = progress or (lambda p: None)
    paths = {name: output_paths(r, out, frame) for name, r in results.items()}
    number = "" if frame is None else f".{frame:04d}"
    count = sum(len(p) for p in paths.values())
    done = 0
    try:
        with staging.FileSet(out) as files:
            for estimator, result in results.items():
                stems = images.file_stems(result.images)
                for name, targets in paths[estimator].items():
                    maps = {f"{stems[name]}.{result.settings.estimator}.{suffix}{number}.exr": (pictures[name], channels)
                            for suffix, pictures, channels in result.extra_maps()}
                    for target in targets:
                        fmt = target.suffix[1:]
                        raw = f".{result.settings.estimator}.raw." in target.name
                        picture = result.raw_images[name] if raw else result.images[name]
                        half, channels = result.settings.half, None
                        if target.name in maps:  # a directional map or a shadowmask, float32 always
                            (picture, channels), half = maps[target.name], False
                        files.stage(target.name, lambda tmp: images.write_exr(tmp, picture, half=half,
                                                                              channels=channels)
                                    if fmt == "exr" else images.WRITERS[fmt](tmp, picture))
                        done += 1
                        if cancelled():
                            raise BakeCancelled()
                    report(Progress("write", done / max(count, 1), f"Writing {name}"))
            for estimator, result in results.items():
                result.files = {name: [str(p) for p in targets] for name, targets in paths[estimator].items()}
            for result in results.values():
                if result.probes:  # probes.npz, or probes.<frame>.npz for a frame of a range
                    stem, suffix = probe_grid.FILE_NAME.rsplit(".", 1)
                    name = f"{stem}{number}.{suffix}"
                    files.stage(name, lambda tmp, grids=result.probes: probe_grid.save(grids, tmp))
                    result.probe_file = str(out / name)
            for name, write_file in (extra or {}).items():  # these may read the results' files
                files.stage(name, write_file)
            seconds = time.perf_counter() - t0
            for result in results.values():
                result.seconds["write"] = seconds
            if frame is None:  # a frame of a range: its report.json is the range's (frames.py)
                content = next(iter(results.values())).report() if summary is None and len(results) == 1 else \
                    {"version": __version__, **(summary or {}), "estimators": {n: r.report() for n, r in results.items()}}
                files.stage_text("report.json", json.dumps(content, indent=2, allow_nan=False))
            if cancelled():
                raise BakeCancelled()
            files.commit()
    except OSError as exc:  # a full disk, a folder gone: nothing of this set is left
        raise BakeError(f"cannot write '{exc.filename or out}': {exc.strerror or exc}") from None
    return None if frame is not None else out / "report.json"
