"""Time fivecal.load_dataset on a large dataset of facet touches.

    python bench/load_dataset.py [--repeat R] [--out FILE] [N ...]   (default: 100000 1000000)

Writes a dataset with N facet observations (the HU40T machine, one facet,
every touch with axes and backlash directions) to a temporary file and prints
the load time (median of R runs, wall and CPU) and where it goes: reading
and decoding the file, the schema check (the head and the first
observations), the C++ loader (every observation parsed and validated) and
the plausibility checks (every observation). Writes the numbers to
bench/load_dataset.json. Loading must stay linear in N: a 1e6-observation
file loads in seconds (it took minutes when the parser tracked the field path
on every value).

    python bench/load_dataset.py --parquet [--out FILE] [N ...]   (default: 1000000 10000000)

The same for Parquet datasets (docs/formats.md, "Columnar datasets"): N 3D
ball (R-test) samples of one mounting on the HU40T, written with pyarrow in
pieces. Each measurement runs in a fresh process, so its peak RSS is its own:
``arrow`` reads every column into Arrow memory (the file's part of any load),
``load`` is fivecal.load_dataset (every observation in the C++ core; skipped
when the machine lacks the memory: about 0.7 KB per observation), ``pieces``
walks the file with fivecal.io.columnar.iter_datasets (10^6 observations at a
time, each piece dropped: the load part of a streaming fit). Writes
bench/load_dataset_parquet.json."""
import argparse
import json
import os
import platform
import resource
import statistics
import sys
import tempfile
import time
import warnings

import fivecal
from fivecal import _core, files, plausibility, schema

HU40T = {"name": "HU40T-like", "topology": "wCBXfZYSt",
         "axes": {"X": {"type": "linear", "direction": [-1, 0, 0]},
                  "B": {"type": "rotary", "direction": [0, -1, 0], "point": [0, 0, -120]},
                  "C": {"type": "rotary", "direction": [0, 0, -1], "point": [0, 0, 0]},
                  "Z": {"type": "linear", "direction": [0, 0, 1]},
                  "Y": {"type": "linear", "direction": [0, 1, 0]},
                  "S": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]}},
         "tool": {"tip": [0, 0, 100]}}


def write_dataset(path: str, n: int) -> int:
    """Writes the dataset text in pieces (a 1e6 list of dicts would dominate
    the memory of the benchmark itself); returns the file size in bytes."""
    head = json.dumps({"machine": HU40T, "probe": {"tip_radius": 3.0},
                       "artefact": {"facets": [{"id": "F1", "point": [0, 0, 10],
                                                "normal": [0, 0, 1]}]}})[:-1]
    with open(path, "w") as f:
        f.write(head + ', "observations": [')
        for i in range(n):
            x = 0.001 * (i % 1000)
            f.write(('' if i == 0 else ',') +
                    '{"type":"facet","target":"F1","axes":{"X":%.6f,"Y":%.6f,"Z":%.6f,'
                    '"B":%d,"C":%d,"S":0},"direction":{"X":1,"Y":-1,"Z":-1}}'
                    % (x, -x, 13.0 + x, (i % 8) * 45 - 180, (i % 5) * 30))
        f.write("]}")
    return os.path.getsize(path)


def stages(path: str) -> dict:
    """Wall seconds of each step of fivecal.load_dataset, run one by one."""
    out = {}
    t = time.perf_counter()
    text = files.read_text(path, "dataset")
    out["read_and_decode_s"] = time.perf_counter() - t
    t = time.perf_counter()
    schema.check_text(text, "dataset", path)
    out["schema_s"] = time.perf_counter() - t
    t = time.perf_counter()
    core = _core.Dataset.from_json(text)
    out["cpp_loader_s"] = time.perf_counter() - t
    del text
    ds = fivecal.Dataset(core)
    t = time.perf_counter()
    plausibility.check_loaded(ds, where=path)
    out["plausibility_s"] = time.perf_counter() - t
    return out


# ---------------------------------------------------------------------------
# Parquet
# ---------------------------------------------------------------------------

def write_parquet_trace(path: str, n: int, piece: int = 1_000_000) -> int:
    """N ball3d samples written in pieces (never the whole trace in memory);
    returns the file size in bytes."""
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    from fivecal.io import columnar

    small = fivecal.ball_dataset(HU40T, "ball3d", {a: [0.0] for a in "XYZBCS"}, [0, 0, 100], [100, 0, 0],
                                 measured=[[0.0, 0.0, 0.0]], setup="R1")
    schema = columnar.dataset_columns(small).schema
    rng = np.random.default_rng(1)
    with pq.ParquetWriter(path, schema, compression="zstd") as w:
        for s in range(0, n, piece):
            m = min(piece, n - s)
            t = np.arange(s, s + m) * 1e-3
            cols = {"type": pa.array(np.full(m, "ball3d", dtype=object), pa.string()),
                    "X": 100 * np.cos(t), "Y": 100 * np.sin(t), "Z": -50 + 10 * np.sin(0.1 * t),
                    "B": 45 * np.sin(0.01 * t), "C": np.degrees(t) % 360 - 180, "S": np.zeros(m),
                    "setup": pa.array(np.full(m, "R1", dtype=object), pa.string())}
            for c, x in zip("xyz", rng.normal(0, 0.002, (3, m))):
                cols[f"measured_{c}"] = x
            for c, x in zip("xyz", (0.0, 0.0, 100.0)):
                cols[f"tool_ball_{c}"] = np.full(m, x)
            for c, x in zip("xyz", (100.0, 0.0, 0.0)):
                cols[f"table_ball_{c}"] = np.full(m, x)
            w.write_table(pa.table({f.name: cols[f.name] for f in schema}, schema=schema))
    return os.path.getsize(path)


def _child(mode: str, path: str) -> dict:
    """One measurement in this (fresh) process."""
    import gc

    t0, c0 = time.perf_counter(), time.process_time()
    if mode == "arrow":
        import pyarrow.parquet as pq

        n = pq.read_table(path).num_rows
    elif mode == "load":
        ds = fivecal.load_dataset(path)
        n = len(ds)
    else:
        from fivecal.io import columnar

        n = 0
        for piece in columnar.iter_datasets(path, rows=1_000_000):
            n += len(piece)
            del piece
            gc.collect()
    return {"mode": mode, "observations": n, "wall_s": time.perf_counter() - t0,
            "cpu_s": time.process_time() - c0,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _available_mb() -> float:
    try:
        with open("/proc/meminfo") as f:
            return next(int(ln.split()[1]) for ln in f if ln.startswith("MemAvailable")) / 1024
    except (OSError, StopIteration):
        return 0.0


def parquet_main(args, doc) -> None:
    import subprocess

    doc["note"] = ("Parquet datasets of N ball3d samples: each mode in a fresh process (its own peak RSS); "
                   "arrow = pyarrow.parquet.read_table alone, load = fivecal.load_dataset (the whole dataset "
                   "in the C++ core), pieces = fivecal.io.columnar.iter_datasets by 10^6 (the load part of "
                   "a streaming fit); the machine may be shared (load average recorded)")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            path = os.path.join(tmp, f"trace{n}.parquet")
            t = time.perf_counter()
            size = write_parquet_trace(path, n)
            entry = {"observations": n, "file_mb": size / 1e6, "write_s": time.perf_counter() - t, "modes": {}}
            for mode in ("arrow", "load", "pieces"):
                if mode == "load" and n * 0.9e-3 > 0.8 * _available_mb():
                    entry["modes"][mode] = {"skipped": f"needs about {n * 0.9e-3:.0f} MB, "
                                                       f"{_available_mb():.0f} MB available"}
                    print(f"parquet {n:>9d}: {mode}: skipped ({entry['modes'][mode]['skipped']})", flush=True)
                    continue
                out = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", mode, path],
                                     capture_output=True, text=True)
                if out.returncode:
                    entry["modes"][mode] = {"failed": out.stderr.strip().splitlines()[-1:]}
                    print(f"parquet {n:>9d}: {mode}: failed: {out.stderr.strip()[-300:]}", flush=True)
                    continue
                r = json.loads(out.stdout.strip().splitlines()[-1])
                entry["modes"][mode] = r
                print(f"parquet {n:>9d} samples, {size / 1e6:7.1f} MB: {mode:6s} {r['wall_s']:6.2f} s wall, "
                      f"{r['cpu_s']:6.2f} s CPU ({r['wall_s'] / n * 1e6:.2f} us per sample), "
                      f"peak RSS {r['peak_rss_mb']:.0f} MB", flush=True)
            doc["results"].append(entry)
            os.remove(path)


def main(argv):
    if argv[:1] == ["--child"]:
        warnings.simplefilter("ignore", fivecal.UnitsWarning)
        print(json.dumps(_child(argv[1], argv[2])))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parquet", action="store_true", help="time Parquet datasets of ball3d samples "
                    "(default sizes 1e6 1e7)")
    ap.add_argument("sizes", nargs="*", type=lambda a: int(float(a)), default=None)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    here = os.path.dirname(os.path.abspath(__file__))
    if not args.sizes:
        args.sizes = [1_000_000, 10_000_000] if args.parquet else [100_000, 1_000_000]
    if args.out is None:
        args.out = os.path.join(here, "load_dataset_parquet.json" if args.parquet else "load_dataset.json")
    warnings.simplefilter("ignore", fivecal.UnitsWarning)  # one facet far from its touches, on purpose
    doc = {"machine": {"cpu": platform.processor(), "cores": os.cpu_count(), "python": platform.python_version(),
                       "fivecal": fivecal.__version__, "platform": platform.platform(),
                       "date": time.strftime("%Y-%m-%d %H:%M:%S"),
                       "load_average_at_start": list(os.getloadavg())},
           "note": "wall and CPU seconds of fivecal.load_dataset end to end (median of the runs); stages "
                   "measured once more, step by step; the machine may be shared (load average recorded)",
           "results": []}
    try:
        with open("/proc/cpuinfo") as f:
            doc["machine"]["cpu"] = next(ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    if args.parquet:
        parquet_main(args, doc)
        doc["machine"]["load_average_at_end"] = list(os.getloadavg())
        with open(args.out, "w") as f:
            json.dump(doc, f, indent=1)
            f.write("\n")
        print(f"written to {args.out}")
        return
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            path = os.path.join(tmp, f"ds{n}.json")
            size = write_dataset(path, n)
            walls, cpus = [], []
            for _ in range(args.repeat):
                t0, c0 = time.perf_counter(), time.process_time()
                ds = fivecal.load_dataset(path)
                walls.append(time.perf_counter() - t0)
                cpus.append(time.process_time() - c0)
                assert len(ds) == n
                del ds
            dt = statistics.median(walls)
            st = stages(path)
            print(f"load_dataset: {n:>9d} observations, {size / 1e6:7.1f} MB: {dt:6.2f} s wall, "
                  f"{statistics.median(cpus):6.2f} s CPU ({dt / n * 1e6:.2f} us per observation); "
                  + ", ".join(f"{k[:-2].replace('_', ' ')} {v:.2f} s" for k, v in st.items())
                  + f"; peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB", flush=True)
            rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
            doc["results"].append({"observations": n, "file_mb": size / 1e6, "wall_s": dt,
                                   "peak_rss_mb_so_far": rss,
                                   "cpu_s": statistics.median(cpus), "runs_wall_s": walls, "runs_cpu_s": cpus,
                                   "us_per_observation": dt / n * 1e6, "stages": st})
            os.remove(path)
    doc["machine"]["load_average_at_end"] = list(os.getloadavg())
    with open(args.out, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    print(f"written to {args.out}")


if __name__ == "__main__":
    main(sys.argv[1:])
