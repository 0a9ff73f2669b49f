"""Regenerates hu40t_table_4_2.json: the thesis Table 4-2 TANGO plan on the
HU40T-like machine as a simulation spec, the candidate pool of
``fivecal design`` (run from this folder: ``python make_hu40t_spec.py``)."""
import json
import pathlib

from fivecal.procedures import tango

m, art = tango.hu40t_machine(), tango.octagonal_table()
plan = tango.hu40t_plan(art, m)
errors = dict(tango.thesis_s3_errors())
errors.update(tango.STYLUS_OFFSETS)
spec = {"_comment": "Thesis Table 4-2 TANGO plan on the HU40T-like machine (fivecal.procedures.tango.hu40t_plan): "
                    "28 visits, the candidate pool of `fivecal design`; also a simulation spec (Table 4-5 "
                    "sized S3 errors, stylus offsets, facet offsets, 0.6 um probing noise). Regenerate with "
                    "examples/design/make_hu40t_spec.py.",
        "machine": "../machines/hu40t.json", "probe": {"tip_radius": tango.TIP_RADIUS}, "artefact": art,
        "errors": errors, "setup": tango.hu40t_setup(art), "sigma": tango.PROBE_SIGMA, "seed": 1}
lines = ["{"] + [f" {json.dumps(k)}: {json.dumps(v)}," for k, v in spec.items()]
lines += [' "plan": [', ",\n".join("  " + json.dumps(e) for e in plan), " ]", "}"]
out = pathlib.Path(__file__).with_name("hu40t_table_4_2.json")
out.write_text("\n".join(lines) + "\n")
print(f"{len(plan)} touches written to {out}")
