"""The one place measured figures live: benchmarks record what they measured into
`benchmarks/measured/<benchmark>.json` (committed, with the commit, the date and the core count),
and the docs' figures are rendered from those files, never typed.

A doc holds a figure as a marked block,

    <!-- measured levels.phases -->
    ...rendered text...
    <!-- /measured -->

whose text is `BLOCKS["levels.phases"]` applied to `measured/levels.json`. After a benchmark ran
with `--record`:

    python benchmarks/measured.py --write     # re-render every block in README.md and docs/
    python benchmarks/measured.py --check     # exit 1 where a block differs (tests/test_benchmarks.py)
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDER = Path(__file__).resolve().parent / "measured"
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
# A block's marker lines may be indented (a block inside a list item): its text is indented alike.
BLOCK = re.compile(r"^(?P<indent>[ ]*)<!-- measured (?P<name>[\w.]+) -->\n(?P<body>.*?)^(?P=indent)<!-- /measured -->",
                   re.S | re.M)


def record(benchmark: str, data: dict) -> Path:
    """`data` as `measured/<benchmark>.json`, with where and when it was measured."""
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    FOLDER.mkdir(exist_ok=True)
    path = FOLDER / f"{benchmark}.json"
    meta = {"commit": commit, "date": datetime.date.today().isoformat(), "cores": os.cpu_count()}
    path.write_text(json.dumps({"recorded": meta, **data}, indent=1, allow_nan=False) + "\n")
    return path


def load(benchmark: str) -> dict:
    return json.loads((FOLDER / f"{benchmark}.json").read_text())


def _levels_table(d: dict) -> str:
    rows = ["| size | texels | photons (automatic) | rasterise | validity | fragments | direct | trace | "
            "estimate | denoise | total | peak MB | OIDN alone | whole |", "|" + "---|" * 14]
    for r in d["phases"]:
        s = r["seconds"]
        rows.append(f"| {r['size']}² | {r['texels']:,} | {r['photons'] / 1e6:.3g}M | "
                    + " | ".join(f"{s.get(k, 0):.1f}" for k in
                                 ("rasterise", "validity", "fragments", "direct", "trace", "estimate", "denoise"))
                    + f" | {r['wall']:.1f} | {r['peak_mb']:,.0f} | {r['oidn_alone']:.1f} | "
                    f"{r.get('oidn_whole', 0):.1f} |")
    m = d["recorded"]
    return "\n".join(rows) + f"\n\n*{d['faces']:,} faces; {m['cores']} cores; commit {m['commit']}, {m['date']}.*\n"


def _levels_sentence(d: dict) -> str:
    parts = []
    for r in d["phases"]:
        s = r["seconds"]
        peak = f"{r['peak_mb'] / 1000:.1f} GB" if r["peak_mb"] >= 1000 else f"{r['peak_mb']:.0f} MB"
        parts.append(f"at {r['size']}² rasterise {s.get('rasterise', 0):.1f}, validity {s.get('validity', 0):.1f}, "
                     f"fragments {s.get('fragments', 0):.1f}, direct {s.get('direct', 0):.1f}, trace "
                     f"{s.get('trace', 0):.1f}, estimate {s.get('estimate', 0):.1f}, denoise "
                     f"{s.get('denoise', 0):.1f} (total {r['wall']:.1f}, peak {peak}; OIDN alone on one image "
                     f"of that size {r['oidn_alone']:.1f} in tiles, {r.get('oidn_whole', 0):.1f} whole)")
    m = d["recorded"]
    return _paragraph(f"On a level of {d['faces']:,} faces with a Smart UV unwrap (`benchmarks/levels.py`, "
                      f"defaults, {m['cores']} cores, seconds, commit {m['commit']}): " + "; ".join(parts) + ".")


def _memory_sentence(d: dict) -> str:
    rows = {r["estimator"]: r for r in d["results"]}
    said = [f"{name} at {r['measured_per_texel']:.0f} bytes a texel (estimate {r['estimate_per_texel']:.0f})"
            for name, r in rows.items()]
    m = d["recorded"]
    return _paragraph(f"Measured with `benchmarks/memory.py` ({d['resolution']}² lightmap, {100 * d['gutter']:.0f} % "
                      f"gutter, {d['photons'] / 1e6:.3g}M photons, peak resident memory less that of a 32² bake, "
                      f"{m['cores']} cores, commit {m['commit']}): " + "; ".join(said) + ".")


def _race_table(d: dict) -> str:
    """benchmarks/race.py's rows: ours per photon count, the first checkout (before) beside the last
    (after), then Cycles + OIDN per sample count."""
    codes = d["codes"]
    ours = {code: {r["asked"]: r for r in d["rows"] if r.get("code") == code} for code in codes}
    first, last = ours[codes[0]], ours[codes[-1]]
    rows = ["| method | error before | seconds | error after | seconds |", "|---|---:|---:|---:|---:|"]
    for asked in sorted(last, key=lambda a: (a == 0, a)):
        a, b = first.get(asked), last[asked]
        name = f"ours, automatic ({b['photons'] / 1e6:.2g}M)" if asked == 0 else f"ours, {asked / 1e6:.3g}M photons"
        before = f"{100 * a['error']:.2f} % | {a['seconds']:.1f}" if a else "| "
        rows.append(f"| {name} | {before} | {100 * b['error']:.2f} % | {b['seconds']:.1f} |")
    for r in d["rows"]:
        if r["method"].startswith("Cycles"):
            rows.append(f"| {r['method']} | {100 * r['error']:.2f} % | {r['seconds']:.1f} | | |")
    m = d["recorded"]
    return "\n".join(rows) + (f"\n\n*{d['scene']} at {d['resolution']}² per object against Cycles at "
                              f"{d['reference_spp']} samples; {m['cores']} cores; commit {m['commit']}, {m['date']}.*\n")


def _paragraph(text: str) -> str:
    return textwrap.fill(text, width=96, break_on_hyphens=False) + "\n"


def _probe_rows(d: dict) -> str:
    rows = ["| estimator | setting | seconds | tracing (the bake's) | error | err²·s |", "|---|---|---|---|---|---|"]
    for r in (r for r in d["rows"] if r["estimator"] != "reference gather"):  # (the reference itself)
        trace = f"{r['trace_seconds']:.2f} s" if r.get("trace_seconds") else "–"
        rows.append(f"| {r['estimator']} | {r['setting']} | {r['seconds']:.3f} | {trace} | "
                    f"{100 * r['error']:.2g} % | {r['error'] ** 2 * r['seconds']:.2g} |")
    m = d["recorded"]
    return "\n".join(rows) + f"\n\n*{d['scene']}, {d['measured']} of {d['probes']} probes measured; {m['cores']} cores; " \
        f"commit {m['commit']}, {m['date']}.*\n"


def _probe_cost(d: dict) -> str:
    c, m = d["cost"], d["recorded"]
    return _paragraph(
        f"**Cost.** `benchmarks/probes.py` bakes the {d['scene']}'s {c['object']} at {c['resolution']}² "
        f"({c['without_photons'] / 1e6:.3g}M photons, shadow rays, OIDN) without probes and with a 16×16×16 Light "
        f"Probe Volume over the scene ({c['probes']:,} probes, {c['invalid']} of them invalid): the probe stage took "
        f"{c['probe_seconds']:.2f} s, {100 * c['probe_seconds'] / c['without_seconds']:.1f} % of the "
        f"{c['without_seconds']:.1f} s bake (the faster of two bakes each, the kernels compiled before; whole bakes "
        f"{100 * c['added']:+.1f} % wall, which on a shared machine is mostly noise; {m['cores']} cores, commit "
        f"{m['commit']}).")


BLOCKS = {
    "levels.phases": ("levels", _levels_table),
    "levels.sentence": ("levels", _levels_sentence),
    "memory.sentence": ("memory", _memory_sentence),
    "probes.estimators": ("probes", _probe_rows),
    "probes.cost": ("probes", _probe_cost),
    "race.table": ("race", _race_table),
}


def render(name: str) -> str:
    benchmark, make = BLOCKS[name]
    return make(load(benchmark))


def blocks(text: str):
    """(name, indent, body) of every marked block in `text`."""
    return [(m["name"], m["indent"], m["body"]) for m in BLOCK.finditer(text)]


def rendered(name: str, indent: str = "") -> str:
    """The block's text as the doc holds it: `render(name)`, every line indented by `indent`."""
    return "".join(indent + line if line.strip() else line for line in render(name).splitlines(True))


def rewrite(text: str) -> str:
    return BLOCK.sub(lambda m: f"{m['indent']}<!-- measured {m['name']} -->\n{rendered(m['name'], m['indent'])}"
                               f"{m['indent']}<!-- /measured -->", text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", action="store_true", help="re-render every block")
    ap.add_argument("--check", action="store_true", help="exit 1 where a block is not its rendering")
    args = ap.parse_args(argv)
    stale = []
    for path in DOCS:
        text = path.read_text()
        new = rewrite(text)
        if new != text:
            stale.append(path.relative_to(ROOT))
            if args.write:
                path.write_text(new)
    for path in stale:
        print(f"{path}: {'rewritten' if args.write else 'a measured block differs from benchmarks/measured/'}")
    return 1 if stale and not args.write else 0


if __name__ == "__main__":
    sys.exit(main())
