"""Mutation checks of the tests issue 47 strengthened: each names a small deliberate bug in the code
under test (one source string replaced by another), applies it to a temporary COPY of the repository
(tpvp/, data_tools/, tests/, benchmarks/, tools/, pyproject.toml; never to this checkout's files), and
runs the test that must catch it there: it must FAIL on the mutant and PASS on the real code.

    .venv/bin/python tools/mutation_check.py                 # every named mutation
    .venv/bin/python tools/mutation_check.py --only helios-species --old
    .venv/bin/python tools/mutation_check.py --file tpvp/x.py --old-text "a" --new-text "b" --test tests/test_x.py::t

``--old`` also runs, on the same mutant, the test as it was before issue 47 (commit ``BEFORE``, read
with ``git show``): PASS there shows the bug the old test let through. The exit status is 0 when every
mutation fails its test and the real code passes it. A tool run by hand (docs/testing.md, "Mutation
checks"), not part of the suite: each check runs its tests twice, single-process.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: What the copy holds: the library, the data tools, the tests and what they read.
COPIED = ("tpvp", "data_tools", "tests", "benchmarks", "tools", "pyproject.toml")
#: The commit before issue 47 strengthened the tests (``--old`` runs its versions of them).
BEFORE = "804b0fb41b7bc36e7669bab563d6d0b4df0cf1ea"


@dataclass(frozen=True)
class Mutation:
    name: str
    bug: str  # what the mutant gets wrong, in words
    file: str  # relative to the repository
    old: str  # the source text replaced (it must occur exactly once)
    new: str
    tests: tuple  # node ids that must fail on the mutant and pass on the real code
    before: tuple = ()  # the node ids of the tests as they were at BEFORE (--old)


MUTATIONS = (
    Mutation("layers-known-current",
             "known() hands the planner today's ground truth as the previous session's model",
             "tpvp/simulate/single_plant.py",
             "return Known(scene.previous, scene.sensor,",
             "return Known(scene.current, scene.sensor,",
             ("tests/test_layers.py::test_a_plan_made_with_the_truth_sealed_is_the_simulation_s_plan",),
             ("tests/test_layers.py::test_the_planner_cannot_reach_the_ground_truth",)),
    Mutation("layers-plugin-loads-simulator",
             "the learned methods' plugin module (loaded by the planner's registries) imports the simulated "
             "world, tpvp.simulate.world",
             "tpvp/learning/methods.py",
             "from tpvp.nbv.methods import NBV_METHODS, NbvContext\n",
             "from tpvp.nbv.methods import NBV_METHODS, NbvContext\nfrom tpvp.simulate.world import Scene  # noqa: F401\n",
             ("tests/test_layers.py::test_the_planner_cannot_reach_the_ground_truth",),
             ("tests/test_layers.py::test_the_planner_cannot_reach_the_ground_truth",)),
    Mutation("organs-countable-not-oracle",
             "the true organ coverage divides by every plant voxel of the organ, the ones no view can see included",
             "tpvp/simulate/single_plant.py",
             "shares = organ_shares(covered, scene.oracle, scene.voxel_organs)",
             "shares = organ_shares(covered, np.flatnonzero(scene.voxel_organs != 0), scene.voxel_organs)",
             ("tests/test_organs.py::test_the_true_organ_coverage_of_a_scene_built_by_hand",
              "tests/test_organs.py::test_organ_targets_are_met_on_the_predicted_surface_with_fewer_views"),
             ("tests/test_organs.py::test_organ_targets_are_met_on_the_predicted_surface_with_fewer_views",)),
    Mutation("season-warm-up-forgotten",
             "run_case measures the true coverage of the planned views only, the warm-up views forgotten",
             "tpvp/simulate/single_plant.py",
             "covered = covered_voxels(scene.truth_visibility, executed + planned)",
             "covered = covered_voxels(scene.truth_visibility, planned)",
             ("tests/test_season.py::test_a_season_equals_its_sessions_chained_by_hand",),
             ("tests/test_season.py::test_a_season_equals_its_sessions_chained_by_hand",)),
    Mutation("replan-last-view-unmeasured",
             "run_case measures the true coverage without the last planned view",
             "tpvp/simulate/single_plant.py",
             "covered = covered_voxels(scene.truth_visibility, executed + planned)",
             "covered = covered_voxels(scene.truth_visibility, executed + planned[:-1])",
             ("tests/test_replan.py::test_a_replanned_run_executes_every_view_once_and_ends_with_nothing_left",),
             ("tests/test_replan.py::test_a_replanned_run_executes_every_view_once_and_ends_with_nothing_left",)),
    Mutation("helios-species",
             "Helios' seed ignores the species: plant 1 of every species grows from the same seed",
             "data_tools/helios.py",
             "np.random.SeedSequence([seed, zlib.crc32(species.encode()), plant])",
             "np.random.SeedSequence([seed, 0, plant])",
             ("tests/test_helios.py::test_the_seed_the_species_and_the_plant_each_change_helios_seed",),
             ("tests/test_helios.py::test_the_same_seed_gives_the_same_bytes_and_another_seed_another_plant",)),
    Mutation("background-cloud-cut",
             "the recording drops the last point of every cloud (an off-by-one)",
             "tpvp/viz/recording.py",
             "rr.Points3D(points, colors=colour, radii=0.0008)",
             "rr.Points3D(points[:-1], colors=colour, radii=0.0008)",
             ("tests/test_background.py::test_the_pool_draws_the_files_drawn_here",),
             ("tests/test_background.py::test_the_pool_draws_the_files_drawn_here",)),
)


def make_copy(dest: Path) -> Path:
    """A copy of what the tests need under ``dest`` (caches kept: the numba kernels stay compiled)."""
    dest.mkdir(parents=True)
    for name in COPIED:
        source = ROOT / name
        if source.is_dir():
            shutil.copytree(source, dest / name, symlinks=True, ignore=shutil.ignore_patterns(".pytest_cache"))
        else:
            shutil.copy2(source, dest / name)
    return dest


def environment(copy: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(copy))
    env.pop("PYTEST_ADDOPTS", None)
    return env


def check_isolated(copy: Path) -> None:
    """The copy's Python imports the copy's tpvp and data_tools, not this checkout's."""
    out = subprocess.run([sys.executable, "-c", "import tpvp, data_tools; print(tpvp.__file__); "
                          "print(data_tools.__file__)"], cwd=copy, env=environment(copy), capture_output=True,
                         text=True, check=True).stdout.split()
    if not all(Path(f).resolve().is_relative_to(copy.resolve()) for f in out):
        sys.exit(f"the copy at {copy} imports {out}, not its own files: refusing to run")


def apply(copy: Path, mutation: Mutation) -> None:
    copy, checkout = copy.resolve(), ROOT.resolve()
    target = (copy / mutation.file).resolve()
    if not target.is_relative_to(copy) or target.is_relative_to(checkout):
        sys.exit(f"refusing to mutate {target}: only a copy outside {checkout} is mutated")
    text = target.read_text()
    if text.count(mutation.old) != 1:
        sys.exit(f"{mutation.name}: {mutation.file} holds the text to replace {text.count(mutation.old)} times "
                 f"(expected once): {mutation.old!r}")
    target.write_text(text.replace(mutation.old, mutation.new))


def pytest(copy: Path, tests, timeout: float) -> tuple[bool, str, float]:
    """(passed, output, seconds) of the node ids run single-process in ``copy``."""
    t = time.perf_counter()
    try:
        run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:xdist", "-p", "no:cacheprovider",
                              "--tb=short", "-rf", *tests], cwd=copy, env=environment(copy), capture_output=True,
                             text=True, timeout=timeout)
    except subprocess.TimeoutExpired as timed_out:
        return False, f"timed out after {timeout:g} s\n{timed_out.stdout or ''}", time.perf_counter() - t
    return run.returncode == 0, run.stdout + run.stderr, time.perf_counter() - t


def failures(output: str) -> list[str]:
    """The failing tests' lines worth reading: the test frames' source lines and the error lines."""
    lines, keep, errors = output.splitlines(), [], 0
    for i, line in enumerate(lines):
        if re.match(r"^_{3,} .* _{3,}$", line):
            keep.append(line.strip("_ ").strip())
        elif re.match(r"^tests/\S+\.py:\d+: in ", line) and i + 1 < len(lines):
            keep.append(f"  {line.split(': in ')[0]}: {lines[i + 1].strip()}")
            errors = 0
        elif line.startswith("E ") and line[1:].strip() and errors < 4:
            keep.append(f"    {line[:220]}")
            errors += 1
    return keep or lines[-15:]


def run(mutations, old: bool, timeout: float, keep: bool) -> int:
    guarded = {m.file for m in mutations}
    digests = {f: hashlib.sha256((ROOT / f).read_bytes()).hexdigest() for f in guarded}
    ok = True
    with tempfile.TemporaryDirectory(prefix="tpvp-mutation-") as folder:
        real = make_copy(Path(folder) / "real")
        check_isolated(real)
        for mutation in mutations:
            mutant = make_copy(Path(folder) / mutation.name)
            apply(mutant, mutation)
            print(f"\n[{mutation.name}] {mutation.file}: {mutation.bug}")
            for sign, text in (("-", mutation.old), ("+", mutation.new)):
                print("\n".join(f"  {sign} {line.strip()}" for line in text.strip("\n").splitlines()))
            passed, output, seconds = pytest(mutant, mutation.tests, timeout)
            print(f"  mutant: {'PASS (NOT CAUGHT)' if passed else 'FAIL (caught)'} ({seconds:.0f} s)")
            for line in ([] if passed else failures(output)):
                print(f"    {line}")
            real_passed, real_output, real_seconds = pytest(real, mutation.tests, timeout)
            print(f"  real code: {'PASS' if real_passed else 'FAIL'} ({real_seconds:.0f} s)")
            if not real_passed:
                print("\n".join(f"    {line}" for line in failures(real_output)))
            ok &= not passed and real_passed
            if old and mutation.before:
                for test_file in {node.split("::")[0] for node in mutation.before}:
                    shown = subprocess.run(["git", "show", f"{BEFORE}:{test_file}"], cwd=ROOT, capture_output=True,
                                           text=True)
                    if shown.returncode:
                        print(f"  before issue 47: cannot read {test_file} at {BEFORE[:7]}: {shown.stderr.strip()}")
                        break
                    (mutant / test_file).write_text(shown.stdout)
                else:
                    before_passed, before_output, before_seconds = pytest(mutant, mutation.before, timeout)
                    print(f"  the test before issue 47 ({BEFORE[:7]}) on the mutant: "
                          f"{'PASS (the bug went through)' if before_passed else 'FAIL'} ({before_seconds:.0f} s)")
            if keep:
                shutil.copytree(mutant, Path(tempfile.gettempdir()) / f"tpvp-mutant-{mutation.name}", dirs_exist_ok=True)
            else:
                shutil.rmtree(mutant)
    changed = [f for f, digest in digests.items() if hashlib.sha256((ROOT / f).read_bytes()).hexdigest() != digest]
    if changed:
        print(f"\nERROR: the checkout's {', '.join(changed)} changed during the run")
        return 2
    caught = "every mutation fails its test, and the real code passes it" if ok else "SOME CHECK DID NOT HOLD"
    print(f"\n{len(mutations)} mutation(s): {caught}")
    return 0 if ok else 1


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", metavar="NAME", choices=[m.name for m in MUTATIONS],
                        help="run these named mutations only")
    parser.add_argument("--list", action="store_true", help="list the named mutations and exit")
    parser.add_argument("--old", action="store_true", help=f"also run the tests as they were at {BEFORE[:7]} on "
                        "each mutant")
    parser.add_argument("--file", help="an ad-hoc mutation: the file (relative to the repository)")
    parser.add_argument("--old-text", help="an ad-hoc mutation: the text replaced (exactly once)")
    parser.add_argument("--new-text", help="an ad-hoc mutation: the text put in its place")
    parser.add_argument("--test", nargs="+", help="an ad-hoc mutation: the node ids that must catch it")
    parser.add_argument("--timeout", type=float, default=900, help="seconds per pytest run (default 900)")
    parser.add_argument("--keep", action="store_true", help="keep each mutant copy under the temporary folder")
    args = parser.parse_args(argv)
    if args.list:
        for m in MUTATIONS:
            print(f"{m.name:<32} {m.file}: {m.bug}\n{'':<32} {', '.join(m.tests)}")
        return 0
    if args.file:
        if not (args.old_text and args.new_text is not None and args.test):
            parser.error("an ad-hoc mutation needs --file, --old-text, --new-text and --test")
        mutations = [Mutation("ad-hoc", "given on the command line", args.file, args.old_text, args.new_text,
                              tuple(args.test))]
    else:
        mutations = [m for m in MUTATIONS if not args.only or m.name in args.only]
    return run(mutations, args.old, args.timeout, args.keep)


if __name__ == "__main__":
    sys.exit(main())
