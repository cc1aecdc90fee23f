"""Start-up (issue 24): light imports, the kernel cache keyed by the kernels' sources, and the
progress shown while the kernels compile."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from planner import _jit
from planner.orchestrator import compiling

HEAVY = ("numpy", "numba", "scipy", "shapely", "pydantic", "daqp", "llvmlite")


def loaded_after(code: str, top: bool = True) -> set[str]:
    """The top-level packages (``top``) or all modules loaded by running ``code`` in a new interpreter."""
    names = "{m.split('.')[0] for m in sys.modules}" if top else "set(sys.modules)"
    probe = f"import sys\n{code}\nimport json\nprint(json.dumps(sorted({names})))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.returncode == 0, out.stderr
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_cli_help_loads_no_numerics():
    mods = loaded_after("from app.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass")
    assert not mods & set(HEAVY), mods & set(HEAVY)


def test_import_planner_loads_no_numerics_and_names_load_on_use():
    assert not loaded_after("import planner") & set(HEAVY)
    mods = loaded_after("import planner\nassert callable(planner.plan)\nassert planner.PlanRequest.__name__")
    assert {"numpy", "numba", "pydantic"} <= mods


def test_compiled_plan_path_loads_no_scipy_shapely_daqp():
    # scipy's linear algebra and graphs, shapely and daqp serve the numpy reference, layouts and the
    # QP fallback only (numba itself imports the bare ``scipy`` package to check its version)
    mods = loaded_after("import planner.orchestrator, planner.schema", top=False)
    assert "numba" in mods
    assert not {m for m in mods if m.split(".")[0] in ("shapely", "daqp") or m.startswith(("scipy.linalg",
                                                                                          "scipy.sparse"))}


def test_import_subcommand_keeps_its_options():
    out = subprocess.run([sys.executable, "-m", "app.cli", "import", "--help"], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0 and "--join-tolerance" in out.stdout and "--units" in out.stdout
    top = subprocess.run([sys.executable, "-m", "app.cli", "--help"], capture_output=True, text=True, timeout=120)
    assert top.returncode == 0 and all(c in top.stdout for c in ("plan", "import", "serve", "batch"))


def test_public_names_resolve_and_unknown_raises():
    import planner

    for name in planner.__all__:
        assert getattr(planner, name) is not None
    with pytest.raises(AttributeError, match="no_such"):
        planner.no_such  # noqa: B018


def test_kernel_cache_dir_precedence(tmp_path):
    tag = _jit.kernel_key()[:16]
    assert _jit.chosen_kernel_cache({"NUMBA_CACHE_DIR": "/seed", "RANGEPLAN_KERNEL_CACHE": "/k"}) == \
        (Path("/seed") / f"rangeplan-{tag}", Path("/seed"))
    assert _jit.chosen_kernel_cache({"RANGEPLAN_KERNEL_CACHE": "/k", "XDG_CACHE_HOME": "/x"}) == \
        (Path("/k") / tag, Path("/k"))
    assert _jit.chosen_kernel_cache({"XDG_CACHE_HOME": "/x"}) == (Path("/x/rangeplan/kernels") / tag, Path("/x"))


def test_kernel_key_covers_every_kernel_module():
    # every module defining cached kernels keys the cache (a callee's change recompiles its callers)
    found = {Path(m.replace("planner.", "").replace(".", "/") + ".py").as_posix()
             for m in compiling.KERNEL_MODULES}
    assert found == set(_jit.KERNEL_SOURCES)
    root = Path(_jit.__file__).parent
    with_njit = {p.relative_to(root).as_posix() for p in root.rglob("*.py")
                 if "@njit" in p.read_text() and p.name != "_jit.py"}
    assert with_njit == set(_jit.KERNEL_SOURCES)


def test_kernels_use_the_keyed_cache():
    # numba's own cache (cache=True), kept beside the keyed copy of each kernel's module
    kernels = compiling.kernel_dispatchers()
    assert len(kernels) >= 40
    for name, d in kernels.items():
        copy = Path(d.py_func.__code__.co_filename)
        assert copy.is_relative_to(_jit.kernel_cache_dir()), name
        assert Path(d.stats.cache_path) == copy.parent / "__pycache__", name


@pytest.mark.slow
def test_a_new_process_loads_what_another_compiled_also_from_a_read_only_seed(tmp_path):
    # a small kernel compiled by one process into a seed (as the image build does), the seed made
    # read-only, copied by app.kernel_cache at start into another NUMBA_CACHE_DIR: the next
    # process loads the kernel from the copy instead of compiling it
    from app.kernel_cache import seed_kernel_cache

    code = ("import json\nimport numpy as np\nfrom planner.model import kernels as k\n"
            "d = k.smallest_singular_values\nd(np.eye(3)[None])\n"
            "s = d.stats\nprint(json.dumps({'hits': sum(s.cache_hits.values()),\n"
            "                  'misses': sum(s.cache_misses.values())}))")

    def run(cache: Path) -> dict:
        env = {"NUMBA_CACHE_DIR": str(cache), "PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "1"}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env,
                             cwd=Path(__file__).resolve().parents[1])
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout.strip().splitlines()[-1])

    seed, cache = tmp_path / "seed", tmp_path / "cache"
    assert run(seed) == {"hits": 0, "misses": 1}
    assert list(seed.glob(f"rangeplan-{_jit.kernel_key()[:16]}/planner/model/__pycache__/*.nbi"))
    for p in seed.rglob("*"):
        p.chmod(0o555 if p.is_dir() else 0o444)
    try:
        assert "copied" in (seed_kernel_cache({"RANGEPLAN_KERNEL_SEED": str(seed), "NUMBA_CACHE_DIR": str(cache)})
                            or "")
        assert run(cache) == {"hits": 1, "misses": 0}
    finally:
        for p in seed.rglob("*"):
            p.chmod(0o755 if p.is_dir() else 0o644)


def _event(name: str) -> SimpleNamespace:
    return SimpleNamespace(data={"dispatcher": SimpleNamespace(py_func=SimpleNamespace(__name__=name))})


def test_progress_estimate_scales_with_this_machine(monkeypatch):
    monkeypatch.setattr(compiling, "COMPILE_COST", {"a": 1.0, "b": 3.0, "c": 4.0})
    monkeypatch.setattr(compiling, "pending_kernels", lambda: ["m.a", "m.b", "m.c"])
    clock = [100.0]
    monkeypatch.setattr(compiling.time, "perf_counter", lambda: clock[0])
    out = io.StringIO()
    p = compiling._Progress(out, interval=3600.0)
    p.on_start(_event("c"))
    assert "compiling 3 kernels" in out.getvalue() and "about 8 s left" in out.getvalue()
    p.on_start(_event("b"))
    clock[0] += 6.0  # b (3 units) took 6 s: this machine runs at half the table's speed
    p.on_end(_event("b"))
    assert p._eta() == pytest.approx(2.0 * 5.0)
    assert "1 of 3 done, 6 s, about 10 s left" in p.line()
    clock[0] += 4.0  # c compiling: counts down
    assert p._eta() == pytest.approx(6.0)
    p.on_end(_event("c"))
    p.on_end(_event("a"))
    assert p._eta() == 0.0
    p.close()
    assert "compiled 3 kernels in 10 s" in out.getvalue()


def test_no_progress_output_when_nothing_compiles():
    out = io.StringIO()
    with compiling.compile_progress(out):
        pass
    assert out.getvalue() == ""


def test_writing_a_plan_loads_no_drawing_reader():
    """``rangeplan plan`` writes its output through ``app.formats``: the machine writers, not the
    drawing and G-code readers (shapely, scipy.spatial: ~0.2 CPU s), which load on first use."""
    mods = loaded_after("import app.formats, planner.orchestrator, planner.exchange", top=False)
    assert not {m for m in mods if m.split(".")[0] in ("shapely", "ezdxf")
                or m.startswith(("scipy.spatial", "scipy.linalg", "scipy.sparse"))}
    assert "shapely" in loaded_after("from planner.exchange import import_drawing, read_gcode")

