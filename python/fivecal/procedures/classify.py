"""Which procedure a dataset ``fivecal identify`` fits comes from, and that
procedure's own values for the result document (docs/formats.md): machined
features are a machining test, touches of an indigenous artefact's facets or
cylinder sections a TANGO run. Here, among the procedures, because naming
the kinds a test uses is what a procedure does (the core API names none)."""
from __future__ import annotations

from typing import Optional

from ..dataset import Dataset
from ..identification import Result

PROBE_TOUCHES = {"facet", "cylinder", "sphere"}


def procedure_of(dataset: Dataset) -> str:
    """The procedure a dataset's observations come from, as ``fivecal
    identify`` names its result: ``machining`` when every observation is a
    machined feature, ``tango`` for touches of an indigenous artefact's
    facets or cylinder sections (with or without spheres and a scale bar),
    else ``identify``."""
    types = set(dataset.observation_types)
    if types == {"machined"}:
        return "machining"
    if types & {"facet", "cylinder"} and types <= PROBE_TOUCHES:
        return "tango"
    return "identify"


def procedure_values(result: Result, procedure: str) -> Optional[dict]:
    """The values ``fivecal identify`` adds to the result document of a
    ``machining`` or ``tango`` fit (docs/formats.md): per machined feature
    its residual (mm); per TANGO run the touches, facets, indexations and
    scale bars that were fitted. None for ``identify``."""
    obs = result.dataset.observations
    if procedure == "machining":
        res = {}
        for r in result.residual_table():
            o = obs[r["observation"]] if r["observation"] >= 0 else {}
            key = r["id"] or f"row{r['row']}"
            res[key] = {"part": o.get("part", ""), "feature": o.get("feature", ""), "residual": r["residual"]}
        return {"features": res}
    if procedure == "tango":
        rotary = [a for a in result.dataset.machine.axis_names if result.dataset.machine.is_rotary(a)]
        touches = [o for o in obs if o.get("type") in PROBE_TOUCHES]
        return {"touches": len(touches),
                "facets": len({o["target"] for o in touches if o.get("type") in ("facet", "cylinder")}),
                "spheres": len({o["target"] for o in touches if o.get("type") == "sphere"}),
                "indexations": len({tuple(round(float(o["axes"].get(a, 0.0)), 6) for a in rotary)
                                    for o in touches}),
                "scale_bars": len(result.dataset.to_dict().get("artefact", {}).get("scale_bars", []))}
    return None
