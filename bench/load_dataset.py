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
on every value)."""
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


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sizes", nargs="*", type=lambda a: int(float(a)), default=[100_000, 1_000_000])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                  "load_dataset.json"))
    args = ap.parse_args(argv)
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
