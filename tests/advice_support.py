"""Apply the remedy a refusal names (issue 31 goal 2: a refusal is a proof or a working
remedy): ``apply_advice(request, message)`` is the request changed as the message's first
remedy says, or None if the message names none. Shared by the tests and benchmarks that
check that advice plans (``tests/test_narrow_gaps.py``, ``benchmarks/bench_gaps.py``).
"""

from __future__ import annotations

import copy
import re

NUM = r"([0-9.]+(?:e[+-]?\d+)?)"

_CELLS = re.compile(rf"(?:(square|triangle) )?cells of {NUM} m \((\w+)\.cell\.(?:size|shape and \w+\.cell\.size)")
_CLEARANCE = re.compile(rf"a clearance of {NUM} m \((\w+)\.clearance; now [^)]*\)(?: with cells of {NUM} m)? gives")
_PSI = re.compile(rf"psi_range \[([-0-9.e]+), ([-0-9.e]+)\] rad(?: with cells of {NUM} m)? gives")
_SAMPLES = re.compile(rf"settings\.samples_per_segment = (\d+)(?: with layout\.cell\.size = {NUM} m"
                      r"[^()]*(?:\(layout\.cell\.shape = (\w+)\))?)?")
_SETTING = re.compile(rf"settings\.(N|speed_m_s|total_time_s|plant_substeps) = {NUM}")
_SEGMENT_SAMPLES = re.compile(r"settings\.segment_samples x (\d+)")


def apply_advice(request: dict, message: str) -> dict | None:
    """``request`` changed as the first remedy ``message`` names (see the module docstring)."""
    fixed = copy.deepcopy(request)
    fixed.setdefault("settings", {})
    lay = fixed.get("layout")
    if lay is not None and (m := _CELLS.search(message)):
        lay.setdefault("cell", {})
        if m.group(1):
            lay["cell"]["shape"] = m.group(1)
        lay["cell"]["size"] = float(m.group(2))
        return fixed
    if lay is not None and (m := _CLEARANCE.search(message)):
        lay["clearance"] = float(m.group(1))
        if m.group(3):
            lay.setdefault("cell", {})["size"] = float(m.group(3))
        return fixed
    if lay is not None and (m := _PSI.search(message)):
        lay["psi_range"] = [float(m.group(1)), float(m.group(2))]
        if m.group(3):
            lay.setdefault("cell", {})["size"] = float(m.group(3))
        return fixed
    # an infeasible plan's advice: the clause that says what plans (not those that do not)
    clause = next((c for c in message.split("; ") if re.search(r"\bplans\b", c) and "do not plan" not in c), None)
    if clause is None:
        return None
    if "settings.fastest plans" in clause:
        for key in ("speed_m_s", "total_time_s", "samples_per_segment", "segment_samples"):
            fixed["settings"].pop(key, None)
        fixed["settings"]["fastest"] = True
        return fixed
    if m := re.match(r"settings\.N = (\d+) with \d+x the time \((.*)\) plans", clause):
        fixed["settings"]["N"] = int(m.group(1))
        clause = m.group(2)  # and the timing, below
    if m := _SAMPLES.search(clause):
        fixed["settings"]["samples_per_segment"] = int(m.group(1))
        for key in ("speed_m_s", "total_time_s"):
            fixed["settings"].pop(key, None)
        if m.group(2) and lay is not None:
            lay.setdefault("cell", {})["size"] = float(m.group(2))
            if m.group(3):
                lay["cell"]["shape"] = m.group(3)
        return fixed
    if m := _SEGMENT_SAMPLES.search(clause):
        f = int(m.group(1))
        fixed["settings"]["segment_samples"] = [c * f for c in fixed["settings"]["segment_samples"]]
        return fixed
    if m := _SETTING.search(clause):
        key, value = m.group(1), m.group(2)
        fixed["settings"][key] = int(value) if key in ("N", "plant_substeps") else float(value)
        if key == "N" and not any(fixed["settings"].get(k) not in (None, False) for k in
                                  ("speed_m_s", "total_time_s", "samples_per_segment", "segment_samples", "fastest")):
            # a longer horizon at the same timing: the samples a segment the request had
            from planner import parse_request

            fixed["settings"]["samples_per_segment"] = int(parse_request(request).settings.samples_per_segment)
        return fixed
    return None
