"""The core's shape, as docs/architecture.md draws it: folders in the data's order, imports that run
one way, no private names borrowed across modules, and no long functions outside compiled kernels.
Read from the source with `ast`, so it needs neither bpy nor a built kernel."""
import ast
from pathlib import Path

import pytest

CORE = Path(__file__).resolve().parents[1] / "detp_bake"
# A folder may import its own modules and those of folders of a lower rank; blender/ (the adapter)
# reads the core's data types and lights, and only the command line reaches into it (lazily).
RANK = {"base": 0, "lightmap": 1, "transport": 2, "estimators": 3, "probes": 4, "run": 5, "cli": 6}
BLENDER_MAY = {"base", "lightmap", "transport", "probes"}
LONGEST = 80  # lines a function may have, compiled kernels aside


def _modules():
    for path in sorted(CORE.rglob("*.py")):
        if "__pycache__" in path.parts or path.name == "__main__.py":
            continue
        parts = list(path.relative_to(CORE.parent).with_suffix("").parts)
        package = parts[-1] == "__init__"
        yield ".".join(parts[:-1] if package else parts), package, path


def _folder(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and (CORE / parts[1]).is_dir() else "base"


def _top_level_imports(module, package, tree, anywhere=False):
    """(target module, imported names, node) of each import that runs when the module loads:
    the module's body, not functions, not `if TYPE_CHECKING:` blocks (`anywhere`: every import the
    module holds, in functions and type-checking blocks too; absolute ones as well)."""
    for node in (ast.walk(tree) if anywhere else tree.body):
        if anywhere and isinstance(node, ast.ImportFrom) and not node.level and node.module:
            yield node.module, [a.name for a in node.names], node
        elif anywhere and isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, [], node
        elif isinstance(node, ast.ImportFrom) and node.level:
            base = module.split(".") if package else module.split(".")[:-1]
            if node.level > 1:
                base = base[:len(base) - node.level + 1]
            target = ".".join(base + ([node.module] if node.module else []))
            yield target, [a.name for a in node.names], node


def _graph(anywhere=False):
    graph, modules = {}, {m: (p, path) for m, p, path in _modules()}
    for module, (package, path) in modules.items():
        edges = set()
        for target, names, _ in _top_level_imports(module, package, ast.parse(path.read_text()), anywhere):
            subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in modules]
            edges.update(subs or ([target] if target in modules else []))
        graph[module] = edges - {module}
    return graph


def test_no_module_imports_itself_back_not_even_lazily():
    """No circle, counting imports inside functions and type-checking blocks: a lazy import that closes
    a circle is a layering the code hides, not one it has."""
    graph = _graph(anywhere=True)
    seen, stack, cycles = {}, [], []

    def visit(m):
        seen[m] = "open"
        stack.append(m)
        for t in sorted(graph[m]):
            if seen.get(t) == "open":
                cycles.append(stack[stack.index(t):] + [t])
            elif t not in seen:
                visit(t)
        stack.pop()
        seen[m] = "done"
    for m in sorted(graph):
        if m not in seen:
            visit(m)
    assert not cycles, cycles


def test_folders_import_in_the_datas_order():
    wrong = []
    for module, targets in _graph().items():
        here = _folder(module)
        for target in targets:
            there = _folder(target)
            if here == there or target == "detp_bake":
                continue
            ok = there in BLENDER_MAY if here == "blender" else \
                there != "blender" and RANK[there] <= RANK[here]
            if not ok:
                wrong.append(f"{module} ({here}) imports {target} ({there})")
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("check", ["private names", "long functions"])
def test_modules_keep_their_own_secrets_and_functions_short(check):
    found = []
    for module, package, path in _modules():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if check == "private names" and isinstance(node, ast.ImportFrom) and node.level:
                found += [f"{module}: {a.name}" for a in node.names if a.name.startswith("_") and
                          not a.name.startswith("__")]
            elif check == "long functions" and isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                compiled = any("jit" in ast.unparse(d) or "inline" in ast.unparse(d) for d in node.decorator_list)
                length = node.end_lineno - node.lineno + 1
                if length > LONGEST and not compiled:
                    found.append(f"{module}.{node.name}: {length} lines")
    assert not found, found


def test_the_estimators_declared_in_options_are_the_registered_ones():
    """options.ESTIMATORS names them for the panel and the help; the registry holds the code: the same
    names in the same order, each with its label (the registry knows nothing of the options' list but it)."""
    from detp_bake import estimators, options
    assert estimators.names() == [name for name, _, _ in options.ESTIMATORS]
    assert [(n, estimators.get(n).label) for n in estimators.names()] == \
        [(name, label) for name, label, _ in options.ESTIMATORS]


def test_the_readmes_memory_figures_are_the_estimates():
    """README's per-texel bytes are the memory estimate's own constants (run/memory.py and each
    estimator's bytes_per_texel), so the page cannot keep a figure the code has dropped."""
    import re
    from detp_bake import estimators
    from detp_bake.run import memory
    text = " ".join((CORE.parent / "README.md").read_text().split())
    said = re.search(r"texels \(about (\d+) bytes each, plus the estimator's own: (.*?)\), lightmap images "
                     r"\(about (\d+) bytes a pixel", text)
    assert said, "README: the memory estimate's sentence is gone or reworded"
    assert int(said.group(1)) == memory.TEXEL_BYTES and int(said.group(3)) == memory.PIXEL_BYTES
    found = re.findall(r"(\d+) for (?:the )?([\w ]+?)(?:,|$)", said.group(2))
    assert len(found) == 4, found
    for figure, name in found:
        key = {"texel histogram": "texel_histogram", "photon map": "photon_map"}.get(name, name)
        assert int(figure) == estimators.get(key).bytes_per_texel, (name, figure)


def test_no_file_over_600_lines():
    """One module per idea: a file past 600 lines holds more than one (the extension's own code)."""
    root = CORE.parent
    files = [p for folder in ("detp_bake", "operators", "ui") for p in (root / folder).rglob("*.py")]
    long = {str(p.relative_to(root)): n for p in files + [root / "__init__.py"]
            if (n := len(p.read_text().splitlines())) > 600}
    assert not long, long


def test_a_packages_init_only_hands_names_on():
    """A folder's __init__.py imports and re-exports; the work lives in modules named for it (the
    estimators' registry, whose lookups are the package's own API, aside)."""
    found = []
    for path in CORE.rglob("__init__.py"):
        if path.parent.name == "estimators":
            continue
        tree = ast.parse(path.read_text())
        found += [f"{path.relative_to(CORE.parent)}: {n.name}" for n in tree.body
                  if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))]
    assert not found, found
