"""Time fivecal.save_dataset and `fivecal convert` on long traces.

    python bench/save_dataset.py [--repeat R] [--modes M,M] [--out FILE] [N ...]   (default: 1000000)

N ball3d (R-test) samples of one mounting on the HU40T, built from arrays
(fivecal.ball_dataset, not timed). Each measurement runs in a fresh process,
so its peak RSS (resource.getrusage ru_maxrss) is its own:

  save_json       fivecal.save_dataset(ds, "x.json"), the dataset built in the process
  save_parquet    fivecal.save_dataset(ds, "x.parquet")
  convert_to_parquet   fivecal convert x.json y.parquet (the load included)
  convert_to_json      fivecal convert x.parquet y.json

``rss_base_mb`` is the process's peak before the timed call (Python,
numpy, pyarrow and, for the saves, the dataset itself): what the write
adds is the difference. The files are written durably (fsync), as users'
are, so the wall time includes the disk. The wall time is the median of R runs, the CPU time
that of the same runs; the machine may be shared (load average recorded).
Writes bench/save_dataset.json."""
import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np

import fivecal

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from load_dataset import HU40T  # noqa: E402

MODES = ("save_json", "save_parquet", "convert_to_parquet", "convert_to_json")


def trace(n: int):
    t = np.arange(n) * 1e-3
    axes = {"X": 100 * np.cos(t), "Y": 100 * np.sin(t), "Z": -50 + 10 * np.sin(0.1 * t),
            "B": 45 * np.sin(0.01 * t), "C": np.degrees(t) % 360 - 180, "S": np.zeros(n)}
    measured = np.random.default_rng(1).normal(0, 0.002, (n, 3))
    return fivecal.ball_dataset(HU40T, "ball3d", axes, [0, 0, 100], [100, 0, 0], measured=measured, setup="R1")


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux


def _child(mode: str, n: int, folder: str) -> dict:
    """One measurement in this (fresh) process."""
    from fivecal.cli import main

    if mode.startswith("save"):
        ds = trace(n)
        target = os.path.join(folder, "out." + ("json" if mode == "save_json" else "parquet"))
    else:
        ds = None
        src, target = ((os.path.join(folder, "in.json"), os.path.join(folder, "out.parquet"))
                       if mode == "convert_to_parquet" else
                       (os.path.join(folder, "in.parquet"), os.path.join(folder, "out.json")))
    base = _rss_mb()
    t0, c0 = time.perf_counter(), time.process_time()
    if ds is not None:
        fivecal.save_dataset(ds, target)
    else:
        rc = main(["convert", src, target])
        assert rc == 0, rc
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"mode": mode, "observations": n, "wall_s": wall, "cpu_s": cpu, "rss_base_mb": base,
            "peak_rss_mb": _rss_mb(), "file_mb": os.path.getsize(target) / 1e6}


def main(argv):
    if argv[:1] == ["--child"]:
        warnings.simplefilter("ignore")
        print(json.dumps(_child(argv[1], int(argv[2]), argv[3])))
        return
    if argv[:1] == ["--prepare"]:
        warnings.simplefilter("ignore")
        ds = trace(int(argv[1]))
        fivecal.save_dataset(ds, os.path.join(argv[2], "in.json"))
        fivecal.save_dataset(ds, os.path.join(argv[2], "in.parquet"))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sizes", nargs="*", type=lambda a: int(float(a)), default=None)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--modes", default=",".join(MODES), help="comma-separated, of " + ", ".join(MODES))
    ap.add_argument("--out", default=os.path.join(HERE, "save_dataset.json"))
    args = ap.parse_args(argv)
    args.sizes = args.sizes or [1_000_000]
    modes = [m for m in args.modes.split(",") if m]
    if not modes or set(modes) - set(MODES):
        ap.error(f"--modes: expected some of {', '.join(MODES)}")
    warnings.simplefilter("ignore")
    doc = {"machine": {"cpu": platform.processor(), "cores": os.cpu_count(), "python": platform.python_version(),
                       "fivecal": fivecal.__version__, "platform": platform.platform(),
                       "date": time.strftime("%Y-%m-%d %H:%M:%S"), "load_average_at_start": list(os.getloadavg())},
           "note": __doc__.split("\n\n", 2)[2].strip().replace("\n", " "),
           "results": []}
    try:
        with open("/proc/cpuinfo") as f:
            doc["machine"]["cpu"] = next(ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    for n in args.sizes:
        with tempfile.TemporaryDirectory() as tmp:
            # In a process of its own: Linux keeps a process's peak RSS
            # across fork and exec, so a parent that held the dataset would
            # lend its peak to every measuring child.
            subprocess.run([sys.executable, os.path.abspath(__file__), "--prepare", str(n), tmp], check=True)
            entry = {"observations": n, "modes": {}}
            for mode in modes:
                runs = []
                for _ in range(args.repeat):
                    out = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", mode, str(n), tmp],
                                         capture_output=True, text=True)
                    if out.returncode:
                        runs = [{"failed": out.stderr.strip()[-500:]}]
                        break
                    runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
                if "failed" in runs[0]:
                    entry["modes"][mode] = runs[0]
                    print(f"{mode:20s} {n:>9d}: failed: {runs[0]['failed']}", flush=True)
                    continue
                walls = [r["wall_s"] for r in runs]
                i = walls.index(statistics.median_low(walls))
                r = dict(runs[i], runs_wall_s=walls, runs_cpu_s=[r["cpu_s"] for r in runs],
                         peak_rss_mb_max=max(r["peak_rss_mb"] for r in runs))
                entry["modes"][mode] = r
                print(f"{mode:20s} {n:>9d} samples: {r['wall_s']:6.2f} s wall, {r['cpu_s']:6.2f} s CPU, "
                      f"peak RSS {r['peak_rss_mb']:.0f} MB (base {r['rss_base_mb']:.0f} MB), "
                      f"file {r['file_mb']:.0f} MB; load {os.getloadavg()[0]:.1f}", flush=True)
            doc["results"].append(entry)
    doc["machine"]["load_average_at_end"] = list(os.getloadavg())
    text = json.dumps(doc, indent=1) + "\n"
    with open(args.out, "w") as f:
        f.write(text)
    print(f"written to {args.out}")


if __name__ == "__main__":
    main(sys.argv[1:])
