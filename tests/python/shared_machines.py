"""Machines several test files share."""

# Rotary axes on both sides (C under the workpiece, B in the head): the
# machine the fixed-frame kinds (point, pose, distance) were built for.
TABLE_HEAD = {"name": "table-head", "topology": "wCfXYZBt",
              "axes": {"C": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]},
                       "X": {"type": "linear", "direction": [1, 0, 0]},
                       "Y": {"type": "linear", "direction": [0, 1, 0]},
                       "Z": {"type": "linear", "direction": [0, 0, 1]},
                       "B": {"type": "rotary", "direction": [0, 1, 0], "point": [0, 0, 300]}},
              "tool": {"tip": [0, 0, 150]}}
