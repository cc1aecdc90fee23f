"""Drawings that expand are bounded before they expand (issue 21): nested block references
(DXF INSERT) and grids of them (MINSERT), SVG ``<use>`` references of references, and
thousands of large arcs are refused with ``too_large`` naming the cause in well under 2 s,
where each held a worker until the 30 s limit before (one to 1.35 GB). Each drawing is made
here: ezdxf writes the DXF, the SVG is text. A drawing just within each bound still imports."""

from __future__ import annotations

import time

import pytest

from planner.errors import PlannerError
from planner.exchange import import_drawing
from planner.exchange._budget import MAX_DRAWING_ENTITIES, MAX_DRAWING_VERTICES, MAX_SVG_SEGMENTS
from tests.drawings import dxf_bytes, new_doc

REFUSED_WITHIN_S = 2.0


def nested_blocks(fanout: int, levels: int) -> bytes:
    """Block ``B0`` holds a square; ``Bk`` holds ``fanout`` references to ``B(k-1)``; the
    modelspace one reference to the last: ``fanout ** (levels - 1)`` squares, a few kB."""
    doc = new_doc(4)
    b0 = doc.blocks.new("B0")
    b0.add_lwpolyline([(0, 0), (1, 0), (1, 1), (0, 1)], close=True)
    for k in range(1, levels):
        blk = doc.blocks.new(f"B{k}")
        for i in range(fanout):
            blk.add_blockref(f"B{k - 1}", (2.0 * i * fanout ** (k - 1), 0))
    doc.modelspace().add_blockref(f"B{levels - 1}", (0, 0))
    return dxf_bytes(doc)


def minsert_grid(rows: int, cols: int) -> bytes:
    doc = new_doc(4)
    doc.blocks.new("SQ").add_lwpolyline([(0, 0), (1, 0), (1, 1), (0, 1)], close=True)
    ref = doc.modelspace().add_blockref("SQ", (0, 0))
    ref.grid(size=(rows, cols), spacing=(2, 2))  # a MINSERT: rows x cols references
    return dxf_bytes(doc)


def use_bomb(fanout: int, levels: int) -> bytes:
    """``g0`` a circle, ``gk`` ``fanout`` ``<use>`` of ``g(k-1)``: ``fanout ** levels`` circles."""
    defs = ['<g id="g0"><circle cx="5" cy="5" r="2"/></g>']
    for k in range(1, levels + 1):
        uses = "".join(f'<use href="#g{k - 1}" x="{i}"/>' for i in range(fanout))
        defs.append(f'<g id="g{k}">{uses}</g>')
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="100mm" viewBox="0 0 100 100">'
            f'<defs>{"".join(defs)}</defs><use href="#g{levels}"/></svg>').encode()


def large_arcs(n: int, radius: float = 40.0) -> bytes:
    """``n`` closed paths of two half-circle arcs each (radius in mm)."""
    paths = "".join(f'<path d="M {50 - radius} {50 + i * 1e-3} A {radius} {radius} 0 1 0 {50 + radius} {50 + i * 1e-3} '
                    f'A {radius} {radius} 0 1 0 {50 - radius} {50 + i * 1e-3} Z"/>' for i in range(n))
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="100mm" viewBox="0 0 100 100">'
            f'{paths}</svg>').encode()


def refused(data: bytes, options: dict | None = None) -> tuple[PlannerError, float]:
    """The error and the CPU time [s] it took (this process's: the machine is shared)."""
    t0 = time.process_time()
    with pytest.raises(PlannerError) as e:
        import_drawing(data, options or {})
    return e.value, time.process_time() - t0


@pytest.mark.parametrize("name, data, cause, field", [
    ("nested INSERT", lambda: nested_blocks(10, 8), "block references (INSERT)", "drawing"),  # 10^7 squares
    ("MINSERT grid", lambda: minsert_grid(1000, 1000), "block references (INSERT)", "drawing"),  # 10^6
    ("<use> bomb", lambda: use_bomb(10, 7), "<use> references", "drawing"),  # 10^7 circles
    ("<use> cycle", lambda: use_bomb(1, 1).replace(b'<use href="#g0" x="0"/>', b'<use href="#g1"/>'),
     "reference cycle", "drawing"),
    ("2000 large arcs", lambda: large_arcs(2000), "path segments", "drawing"),
    ("200 huge arcs", lambda: large_arcs(200, 4e4), "vertices in all", "flatten_tolerance"),
])
@pytest.mark.serial  # a bound of 2 s
def test_crafted_drawings_are_refused_before_they_expand(name, data, cause, field):
    err, seconds = refused(data(), {"flatten_tolerance": 1e-6})
    assert err.code == "too_large" and err.field == field, (name, err)
    assert cause in err.message, (name, err.message)
    assert seconds < REFUSED_WITHIN_S, (name, seconds)


def test_drawings_within_the_bounds_still_import():
    """The bounds refuse what expands past them, not what is merely nested: 3 levels of 4
    references (64 squares) and a 10 x 10 MINSERT grid import with every square, and a few
    large arcs are flattened as before."""
    res = import_drawing(nested_blocks(4, 4), {})
    assert len(res.layout.obstacles) == 4 ** 3
    res = import_drawing(minsert_grid(10, 10), {})
    assert len(res.layout.obstacles) == 100
    res = import_drawing(use_bomb(3, 2), {})
    assert res.report.ignored.get("use", 0) == 0 or res.layout.obstacles
    res = import_drawing(large_arcs(3), {"flatten_tolerance": 1e-6})
    assert len(res.layout.obstacles) == 1  # three coincident circles, one shape (y offsets of 1 um)


def test_the_bounds_are_the_documented_ones():
    # the counts that name the bound in each message are the module's constants
    err, _ = refused(nested_blocks(10, 8))
    assert str(MAX_DRAWING_ENTITIES) in err.message
    err, _ = refused(large_arcs(200, 4e4), {"flatten_tolerance": 1e-6})
    assert str(MAX_DRAWING_VERTICES) in err.message
    err, _ = refused(large_arcs(2000))
    assert str(MAX_SVG_SEGMENTS) in err.message
