"""The package's layout rules (docs/pages/reference/layout.md), checked on the source with ``ast``.

Floors from the bottom up; a module imports only from its own floor or below.  No import cycle,
counting the imports inside functions too.  Only the application floor parses arguments, prints
or draws.  Sinks see the stream's strips, not the pipeline.  No module over 500 lines.  Every
package is installed by ``pip install .``.
"""

import ast
import sys
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "rtsar"

FLOORS = [
    {
        "rtsar",
        "rtsar.params",
        "rtsar.fft_lengths",
        "rtsar.presets",
        "rtsar.windows",
        "rtsar.instrument",
        "rtsar.phase",
        "rtsar.samples",
        "rtsar.version",
        "rtsar.child",
    },
    {"rtsar.lens"},
    {"rtsar.physical"},
    {"rtsar.ccd"},
    {"rtsar.focus"},
    {"rtsar.topo"},
    {"rtsar.scene"},
    # spotlight: simulates with the scene model's synthesis, forms images with numpy only
    {"rtsar.spot"},
    {"rtsar.sources"},
    {"rtsar.stream"},
    {"rtsar.sinks"},
    {"rtsar.analysis"},
    {"rtsar.app", "rtsar.__main__"},
]

# Imports inside functions, each with its reason: the cost of loading what few runs need.
# An import placed in a function to dodge an import cycle does not belong here.
LAZY_ALLOWED = {
    ("rtsar.lens.base", "rtsar.lens.opencl"): "pyopencl loads slowly; the NumPy lens needs none",
    ("rtsar.lens.base", "rtsar.lens.cl_loader"): "pyopencl loads slowly; probed for --lens auto",
    ("rtsar.app.bench", "rtsar.lens.cl_loader"): "bench runs without pyopencl where OpenCL fails",
    ("rtsar.lens.base", "rtsar.lens.auto"): "pyopencl loads slowly; --lens auto only",
    ("rtsar.app.cli.files", "rtsar.lens.auto"): "pyopencl loads slowly; --lens auto only",
    ("rtsar.lens.base", "rtsar.lens.cl_devices"): "pyopencl loads slowly; OpenCL lenses only",
    ("rtsar.app.devices", "rtsar.lens.cl_devices"): "pyopencl may fail to load: said in one line",
    ("rtsar.app.devices", "rtsar.lens.cl_vendors"): "imported with cl_devices, after pyopencl",
    ("rtsar.app.devices", "rtsar.lens.cl_probe"): "imported with cl_devices, after pyopencl",
    ("rtsar.ccd", "rtsar.ccd.physical"): "the physical CCD's numba kernels, physical mode only",
    ("rtsar.scene", "rtsar.scene.simulator"): "numba loads in ~0.4 s: only when simulating",
    ("rtsar.app.cli.files", "rtsar.scene"): "the simulator (numba) for simulate only",
    ("rtsar.app.cli.files", "rtsar.scene.tones"): "its kernels' compile count, simulate only",
    ("rtsar.app.cli.options", "rtsar.focus.chain"): "the corrections load with --correct only",
    ("rtsar.app.cli.options", "rtsar.scene.correction_context"): "with --correct, --height",
    ("rtsar.app.cli.options", "rtsar.stream.engine"): "a first pass for a bare --correct pra",
    ("rtsar.app.cli.options", "rtsar.topo.sam3d_strips"): "3D loads with --height only",
    ("rtsar.app.cli.options", "rtsar.topo.stream"): "3D loads with --height only",
    ("rtsar.app.cli.inputs", "rtsar.sources.formats.cphd_reader"): "sarkit: CPHD inputs only",
    ("rtsar.app.cli.inputs", "rtsar.sources.formats.sigmf_reader"): "sigmf: SigMF inputs only",
    ("rtsar.ccd", "rtsar.ccd.direct"): "numba loads in ~0.4 s: only the correlators using it",
    ("rtsar.ccd", "rtsar.ccd.doppler_migration"): "numba: the Doppler-domain taps only",
    ("rtsar.ccd", "rtsar.ccd.walk_deskew"): "numba: the walk's ring only",
    ("rtsar.ccd", "rtsar.ccd.nonuniform"): "numba loads in ~0.4 s: only the correlators using it",
    ("rtsar.ccd", "rtsar.ccd.partitioned"): "numba loads in ~0.4 s: only the correlators using it",
    ("rtsar.app.cli.formats", "rtsar.sinks.exports.sicd"): "sarpy loads in ~1 s; --sicd only",
    ("rtsar.app.cli.formats", "rtsar.app.measure_image"): "the measure's theory: --scene only",
    ("rtsar.app.cli.streaming", "rtsar.sinks.exports.sicd"): "sarpy loads in ~1 s; --sicd only",
    ("rtsar.app.cli.view", "rtsar.app.webview.server"): "aiohttp loads in ~0.2 s; --http only",
    ("rtsar.app.entry", "rtsar.app.cli"): "a Ctrl-C during the command's imports is one line",
    ("rtsar.app.cli", "rtsar.app.cli.options"): "rtsar --help and --version load no command",
    ("rtsar.app.cli", "rtsar.app.cli.outputs"): "rtsar --help and --version load no command",
}
MAX_LINES = 500


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


MODULES = modules()


def floor(name: str) -> int:
    if name == "rtsar":
        return 0
    for rank, members in enumerate(FLOORS):
        if any(name == m or name.startswith(m + ".") for m in members - {"rtsar"}):
            return rank
    raise AssertionError(
        f"{name} belongs to no floor: add it to FLOORS (and docs/pages/reference/layout.md)"
    )


def resolve(importer: str, is_package: bool, node: ast.ImportFrom) -> list[str]:
    """The rtsar modules a ``from … import …`` statement loads."""
    if node.level:
        base = importer.split(".")
        if not is_package:
            base = base[:-1]
        base = base[: len(base) - (node.level - 1)]
        target = ".".join(base + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    if not target.startswith("rtsar"):
        return []
    out = []
    for alias in node.names:
        sub = f"{target}.{alias.name}"
        out.append(sub if sub in MODULES else target)
    return out


def imports(name: str) -> list[tuple[str, bool, int]]:
    """(imported rtsar module, inside a function?, line) for every import in ``name``."""
    path = MODULES[name]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_package = path.name == "__init__.py"
    found = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
            if isinstance(child, ast.ImportFrom):
                targets = resolve(name, is_package, child)
                found.extend((t, in_function, child.lineno) for t in targets)
            elif isinstance(child, ast.Import):
                found.extend(
                    (a.name, in_function, child.lineno)
                    for a in child.names
                    if a.name.startswith("rtsar")
                )
            visit(child, inner)

    visit(tree, False)
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, list[tuple[str, bool, int]]]:
    """Every module's imports, parsed when a test asks (not at collection, in every worker)."""
    return {name: imports(name) for name in MODULES}


def test_every_module_sits_on_a_floor():
    for name in MODULES:
        floor(name)


def test_no_module_imports_a_floor_above_its_own(graph):
    upward = [
        f"{name}:{line} imports {target} (floor {floor(target)} > {floor(name)})"
        for name, edges in graph.items()
        for target, _, line in edges
        if floor(target) > floor(name)
    ]
    assert not upward, "\n".join(upward)


def test_no_import_cycles(graph):
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    stack: list[str] = []
    cycles = []

    def walk(name):
        state[name] = 1
        stack.append(name)
        for target, _, _ in graph.get(name, []):
            if target not in MODULES or target == name:
                continue
            if state.get(target) == 1:
                cycles.append(" → ".join(stack[stack.index(target) :] + [target]))
            elif target not in state:
                walk(target)
        stack.pop()
        state[name] = 2

    for name in MODULES:
        if name not in state:
            walk(name)
    assert not cycles, "\n".join(cycles)


def test_imports_inside_functions_are_only_the_listed_ones(graph):
    lazy = {
        (name, target): line
        for name, edges in graph.items()
        for target, inside, line in edges
        if inside
    }
    unlisted = [f"{n}:{line} imports {t} inside a function" for (n, t), line in lazy.items()]
    unlisted = [u for u, key in zip(unlisted, lazy, strict=True) if key not in LAZY_ALLOWED]
    assert not unlisted, "\n".join(unlisted)


def _uses(name: str) -> set[str]:
    """Which of argparse, matplotlib and print() a module uses."""
    tree = ast.parse(MODULES[name].read_text(encoding="utf-8"))
    used = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            used |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            used.add(node.module.split(".")[0])
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id == "print":
                used.add("print")
    return used & {"argparse", "matplotlib", "print"}


def test_only_the_application_floor_parses_prints_or_draws():
    bad = {
        name: sorted(_uses(name))
        for name in MODULES
        if floor(name) < floor("rtsar.app") and _uses(name)
    }
    assert not bad, bad


def test_sinks_see_strips_not_the_pipeline(graph):
    bad = [
        f"{name} imports {target}"
        for name, edges in graph.items()
        if name.startswith("rtsar.sinks")
        for target, _, _ in edges
        if target.startswith("rtsar.stream") and target != "rtsar.stream.strips"
    ]
    assert not bad, bad


@pytest.mark.parametrize("name", sorted(MODULES))
def test_module_size(name):
    lines = MODULES[name].read_text(encoding="utf-8").count("\n")
    assert lines <= MAX_LINES, f"{name} has {lines} lines: split it (STYLE habit 8)"


def test_pyproject_installs_every_package():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    listed = set(config["tool"]["setuptools"]["packages"])
    found = {module_name(p.parent) for p in PACKAGE.rglob("__init__.py")}
    assert found - listed == set(), f"packages missing from pyproject.toml: {found - listed}"
    assert (ROOT / "kernels" / "lens.cl").is_file() and "rtsar.kernels" in listed


def test_docs_layout_names_every_module():
    """docs/pages/reference/layout.md lists every top-level module and package and, per package,
    its modules."""
    text = (ROOT / "docs" / "pages" / "reference" / "layout.md").read_text(encoding="utf-8")
    block = text.split("# Layout", 1)[1].split("```text\n", 1)[1].split("```", 1)[0]
    entries: dict[str, str] = {}
    current = None
    for line in block.splitlines():
        head = line.split()[0] if line.strip() else ""
        if head.startswith("rtsar/"):
            current = head
            entries[current] = line
        elif current:
            entries[current] += " " + line
    words = {w.strip(",():;") for v in entries.values() for w in v.replace("/", "/ ").split()}
    missing = []
    for child in sorted(PACKAGE.iterdir()):
        if child.name.startswith(("_", ".")) or child.suffix not in (".py", ""):
            continue
        if child.is_dir():
            key = f"rtsar/{child.name}/"
            if key not in entries:
                missing.append(key)
                continue
            listed = {w.strip(",():;/") for w in entries[key].split()}
            for sub in sorted(child.iterdir()):
                name = sub.stem if sub.suffix == ".py" else sub.name
                if name.startswith("_") or (sub.is_dir() and not (sub / "__init__.py").exists()):
                    continue
                if name not in listed and f"{name}/" not in entries[key]:
                    missing.append(f"{key}{name}")
        elif f"rtsar/{child.name}" not in words and f"rtsar/{child.name}" not in block:
            missing.append(f"rtsar/{child.name}")
    assert not missing, f"docs/pages/reference/layout.md does not name: {missing}"
