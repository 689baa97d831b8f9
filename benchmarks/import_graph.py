"""The import graph of tpvp/, read from the code (no import is executed): cycles between modules,
upward imports (a stage package importing ``learning`` or ``experiments``, ``learning`` importing
``experiments``) and imports of tpvp modules inside functions, per file.

``python benchmarks/import_graph.py`` prints the three tables and a summary line; it is the
measurement behind issue 25's layering targets (0 cycles, 0 upward imports, <= 20 function-local
imports), not a test.
"""

from __future__ import annotations

import ast
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / "tpvp"
TOP = ("cli", "__main__", "experiments")  # may import anything below them
ABOVE_STAGES = ("learning", "experiments", "cli", "__main__")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> list[tuple[list[str], bool]]:
    """``(imported tpvp names, inside a function?)`` for every import statement of a tpvp module;
    for ``from a.b import c`` the name is ``a.b.c`` (a submodule, or a name that :func:`main`
    resolves to its module ``a.b``)."""
    tree = ast.parse(path.read_text(), str(path))
    package = module_name(path) if path.name == "__init__.py" else module_name(path).rpartition(".")[0]
    found = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                names = [a.name for a in child.names if a.name.split(".")[0] == "tpvp"]
                if names:
                    found.append((names, inside))
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    parent = package.split(".")[: len(package.split(".")) - child.level + 1]
                    base = ".".join(parent + ([base] if base else []))
                if base.split(".")[0] == "tpvp":
                    found.append(([f"{base}.{a.name}" for a in child.names], inside))
            visit(child, inside)

    visit(tree, False)
    return found


def layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def upward(source: str, target: str) -> bool:
    src, dst = layer(source), layer(target)
    if src in TOP:
        return False
    if src == "learning":
        return dst in ("experiments", "cli", "__main__")
    return dst in ABOVE_STAGES


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, on_stack, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in graph:
                    continue
                if child not in index:
                    index[child] = low[child] = counter[0]
                    counter[0] += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        out.append(sorted(component))
    return out


def main() -> int:
    files = sorted(ROOT.rglob("*.py"))
    modules = {module_name(p) for p in files}

    def resolve(target: str) -> str:
        while target and target not in modules:
            target = target.rpartition(".")[0]
        return target

    graph, local, up = {}, Counter(), set()
    for path in files:
        source = module_name(path)
        graph.setdefault(source, set())
        for names, inside in imports(path):
            targets = {resolve(name) for name in names} - {"", source}
            if inside and targets:
                local[path.relative_to(ROOT.parent).as_posix()] += 1
            for target in targets:
                graph[source].add(target)
                if upward(source, target):
                    up.add((source, target, "in a function" if inside else "at the top"))
    found = cycles(graph)
    print(f"{'cycle':>5}  modules")
    for k, component in enumerate(found, 1):
        print(f"{k:>5}  {len(component)}: {', '.join(component)}")
    print(f"\n{'upward import':<60} where")
    for source, target, where in sorted(up):
        print(f"{source + ' -> ' + target:<60} {where}")
    print(f"\n{'function-local tpvp import statements':<45} count")
    for file, count in local.most_common():
        print(f"{file:<45} {count}")
    print(f"\n{len(found)} cycles ({sum(map(len, found))} modules), {len(up)} upward imports, "
          f"{sum(local.values())} function-local tpvp import statements in {len(local)} files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
