"""Time fivecal.load_dataset on a large dataset of facet touches.

    python bench/load_dataset.py [N ...]        (default: 100000 1000000)

Writes a dataset with N facet observations (the HU40T machine, one facet,
every touch with axes and backlash directions) to a temporary file and prints
the load time. Loading must stay linear in N: a 1e6-observation file loads in
seconds (it took minutes when the parser tracked the field path on every
value)."""
import json
import os
import sys
import tempfile
import time

import fivecal

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


def main(argv):
    sizes = [int(float(a)) for a in argv] or [100_000, 1_000_000]
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            path = os.path.join(tmp, f"ds{n}.json")
            size = write_dataset(path, n)
            t0 = time.perf_counter()
            ds = fivecal.load_dataset(path)
            dt = time.perf_counter() - t0
            assert len(ds) == n
            print(f"load_dataset: {n:>9d} observations, {size / 1e6:7.1f} MB: {dt:6.2f} s "
                  f"({dt / n * 1e6:.2f} us per observation)", flush=True)
            del ds
            os.remove(path)


if __name__ == "__main__":
    main(sys.argv[1:])
