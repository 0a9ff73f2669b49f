"""Mean model error of a point fit, overall and per moving joint.

The model error of one measured point is |predicted - measured|, the length
of its 3-row residual vector (mm); the SScanSS-2 project reports its mean
over the points. Rows are grouped by the axis that is away from its home
(the joint that moved); a row at the home pose is counted with the joint
measured around it (the row before it, or after it for the first row).

    python3 model_error.py RESULT.json DATASET.json
"""
from __future__ import annotations

import json
import sys

import numpy as np


def model_errors(result: dict, dataset: dict) -> dict:
    """{'all': mean mm, '<axis>': mean mm of the rows where that axis moved}."""
    obs = dataset["observations"]
    e = np.asarray(result["residuals"], dtype=float)
    if e.size != 3 * len(obs):
        raise ValueError(f"{e.size} residual rows for {len(obs)} point observations (3 each expected)")
    dist = np.linalg.norm(e.reshape(-1, 3), axis=1)
    # an axis' home is the value it keeps while the others move: its most common value
    home = {}
    for a in obs[0]["axes"]:
        vals = [o["axes"][a] for o in obs]
        home[a] = max(set(vals), key=vals.count)
    joints = []
    for o in obs:
        moved = [a for a in o["axes"] if o["axes"][a] != home[a]]
        joints.append(moved[0] if len(moved) == 1 else None)
    # the home pose belongs to the joint measured around it: the row before, else the row after
    for i in list(range(1, len(joints))) + list(range(len(joints) - 2, -1, -1)):
        if joints[i] is None:
            joints[i] = joints[i - 1] if i > 0 and joints[i - 1] else (joints[i + 1] if i + 1 < len(joints) else None)
    groups: dict = {}
    for j, d in zip(joints, dist):
        groups.setdefault(j, []).append(d)
    out = {"all": float(dist.mean())}
    out.update({str(j): float(np.mean(v)) for j, v in groups.items()})
    return out


def main(argv) -> int:
    if len(argv) != 3:
        print(__doc__.strip().splitlines()[-1].strip(), file=sys.stderr)
        return 2
    with open(argv[1], encoding="utf-8") as f:
        result = json.load(f)
    with open(argv[2], encoding="utf-8") as f:
        dataset = json.load(f)
    for k, v in model_errors(result, dataset).items():
        print(f"{'mean model error' if k == 'all' else '  joint ' + k:>18}: {v:.4f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
