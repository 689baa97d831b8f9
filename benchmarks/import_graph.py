"""The import graph of tpvp/, read from the code (no import is executed): cycles between modules,
upward imports (a foundation importing a stage, a stage package importing ``learning``, ``simulate`` or
``experiments``, ``learning`` importing ``simulate`` or ``experiments``, the simulation importing the
experiments or the command line), imports of tpvp modules inside
functions, and private names (``_x``) imported from another package (by tpvp/ and benchmarks/).

``python benchmarks/import_graph.py`` prints the tables and a summary line; ``tests/test_layers.py``
holds the layering rules (docs/architecture.md) to :func:`analyse`.
"""

from __future__ import annotations

import ast
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / "tpvp"
DATA_TOOLS = ROOT.parent / "data_tools"  # above the library: it may load foundations and stages only
BENCHMARKS = Path(__file__).resolve().parent
OWN = ("tpvp", "data_tools")
TOP = ("cli", "cli_common", "commands", "__main__", "experiments", "session")  # may import anything below them
ABOVE_STAGES = ("config", "config_loading", "pipeline", "learning", "simulate", "experiments", "session", "cli",
                "cli_common", "commands", "__main__")
#: What the simulation (``simulate``: above the planner and the sessions) never imports: what runs it.
ABOVE_SIMULATE = ("learning", "experiments", "cli", "cli_common", "commands", "__main__")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> list[tuple[list[str], bool, int]]:
    """``(imported tpvp names, inside a function?, line)`` for every import statement of a tpvp
    module; for ``from a.b import c`` the name is ``a.b.c`` (a submodule, or a name that
    :func:`analyse` resolves to its module ``a.b``)."""
    tree = ast.parse(path.read_text(), str(path))
    package = module_name(path) if path.name == "__init__.py" else module_name(path).rpartition(".")[0]
    found = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                names = [a.name for a in child.names if a.name.split(".")[0] in OWN]
                if names:
                    found.append((names, inside, child.lineno))
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    parent = package.split(".")[: len(package.split(".")) - child.level + 1]
                    base = ".".join(parent + ([base] if base else []))
                if base.split(".")[0] in OWN:
                    found.append(([f"{base}.{a.name}" for a in child.names], inside, child.lineno))
            visit(child, inside)

    visit(tree, False)
    return found


def layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


#: The foundations: they may import each other and third-party libraries, never a stage.
FOUNDATIONS = ("errors", "registry", "provenance", "parallel", "solvers", "numba_tools", "io", "")


def upward(source: str, target: str) -> bool:
    if target.startswith("data_tools"):
        return not source.startswith("data_tools")  # the library never loads the data tools
    if source.startswith("data_tools"):  # the layers that plan or run experiments are not theirs
        return layer(target) in ("config", "config_loading", "pipeline", "learning", "simulate", "experiments",
                                 "session", "cli", "cli_common", "commands")
    src, dst = layer(source), layer(target)
    if dst == "export":  # a plan written for a robot or a tool: only what runs a plan asks for it
        return src not in ("export", "commands", "cli", "__main__", "session")
    if src in FOUNDATIONS:
        return dst not in FOUNDATIONS
    if src in TOP:
        return False
    if src == "learning":
        return dst in ("simulate", "experiments", "cli", "commands", "__main__")
    if src == "simulate":
        return dst in ABOVE_SIMULATE
    if src == "config_loading":  # builds the configurations that config.py composes
        return dst in ABOVE_STAGES and dst != "config"
    if src == "pipeline":  # above the stages and their configuration, below what runs it
        return dst in ABOVE_STAGES and dst not in ("config", "config_loading", "pipeline")
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


@dataclass
class Report:
    cycles: list  # lists of modules
    upward: set  # (importer, imported, "in a function" | "at the top")
    local: list  # (file, line, source line) of function-local tpvp imports
    private: list  # (file, line, imported private name) across packages
    graph: dict  # module -> the tpvp modules it imports (at the top or in a function)

    def reachable(self, module: str) -> set:
        """Every tpvp module ``module`` loads, directly or through others."""
        seen, todo = set(), [module]
        while todo:
            for target in self.graph.get(todo.pop(), ()):
                if target not in seen:
                    seen.add(target)
                    todo.append(target)
        return seen


def is_private(name: str) -> bool:
    last = name.rpartition(".")[2]
    return last.startswith("_") and not last.startswith("__")


def package_of(module: str) -> str:
    """``tpvp.nbv.methods`` -> ``tpvp.nbv``; top-level modules are their own package."""
    parts = module.split(".")
    return ".".join(parts[:2])


def analyse(root: Path = ROOT, others=(BENCHMARKS,), above=(DATA_TOOLS,)) -> Report:
    """The import graph of ``root`` and of the folders ``above`` it (their function-local imports
    are not counted); the private names that ``others`` import."""
    files = sorted(root.rglob("*.py")) + sorted(f for folder in above for f in folder.rglob("*.py"))
    modules = {module_name(p) for p in files}

    def resolve(target: str) -> str:
        while target and target not in modules:
            target = target.rpartition(".")[0]
        return target

    graph, local, up, private = {}, [], set(), []
    for path in files:
        source = module_name(path)
        lines = path.read_text().splitlines()
        graph.setdefault(source, set())
        for names, inside, line in imports(path):
            targets = {resolve(name) for name in names} - {"", source}
            if inside and targets and source.startswith("tpvp"):
                local.append((path.relative_to(root.parent).as_posix(), line, lines[line - 1].strip()))
            for target in targets:
                graph[source].add(target)
                if upward(source, target):
                    up.add((source, target, "in a function" if inside else "at the top"))
            for name in names:
                module = resolve(name)
                if name != module and is_private(name) \
                        and package_of(module) != package_of(source):
                    private.append((path.relative_to(root.parent).as_posix(), line, name))
    for folder in others:
        for path in sorted(folder.rglob("*.py")):
            for names, _, line in imports(path):
                private += [(path.relative_to(root.parent).as_posix(), line, name) for name in names
                            if is_private(name) and resolve(name) != name]
    return Report(cycles(graph), up, local, private, graph)


def main() -> int:
    report = analyse()
    print(f"{'cycle':>5}  modules")
    for k, component in enumerate(report.cycles, 1):
        print(f"{k:>5}  {len(component)}: {', '.join(component)}")
    print(f"\n{'upward import':<60} where")
    for source, target, where in sorted(report.upward):
        print(f"{source + ' -> ' + target:<60} {where}")
    print(f"\n{'function-local tpvp import statements':<45} count")
    for file, count in Counter(file for file, _, _ in report.local).most_common():
        print(f"{file:<45} {count}")
    print(f"\n{'private name imported across packages':<60} where")
    for file, line, name in report.private:
        print(f"{name:<60} {file}:{line}")
    print(f"\n{len(report.cycles)} cycles ({sum(map(len, report.cycles))} modules), {len(report.upward)} upward "
          f"imports, {len(report.local)} function-local tpvp import statements in "
          f"{len({f for f, _, _ in report.local})} files, {len(report.private)} private names imported across packages")
    return 0


if __name__ == "__main__":
    sys.exit(main())
