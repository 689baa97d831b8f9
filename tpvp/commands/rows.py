"""``tpvp greenhouse``: one greenhouse-row pair, planned and executed; the row options every row
command shares."""

from __future__ import annotations

from pathlib import Path

from tpvp.cli_common import add_config_options, configuration_options, print_rows, print_warnings, resolved_config
from tpvp.errors import TpvpError
from tpvp.io.publish import staged_folder
from tpvp.simulate.greenhouse import build_row_scene, run_row_case
from tpvp.simulate.outputs import write_row_case_outputs
from tpvp.simulate.row_cases import QUICK, RowCase, dataset_cases
from tpvp.synthetic.scan import REFERENCES
from tpvp.viz.background import drawing_pool


def row_config(args):
    if args.dataset is not None and args.reference:
        raise TpvpError(f"--reference applies to generated rows; the rows of {args.dataset} are used as they are")
    config = resolved_config(args, extra=QUICK if args.quick else None)
    if config.setting != "row":
        raise TpvpError(f"configuration {config.name!r} is for individual plants; use paper-row or a row YAML file")
    return config


def row_options(p, output, several_references: bool = False):
    configuration_options(p, output, "paper-row")
    p.add_argument("--dataset", type=Path, default=None,
                   help="a folder written by `python -m data_tools greenhouse clean` (Processed_3D_Model/"
                        "<room>_<date>.pcd; default: generated rows, offline)")
    p.add_argument("--reference", nargs="+" if several_references else None, default=None, choices=REFERENCES,
                   help="what of a generated row the reference holds: the complete row, what the room's candidate "
                        "positions see, or an emulated handheld phone capture" +
                        (" (several: each case once per reference, side by side in the tables)"
                         if several_references else "") + " (default: handheld; docs/greenhouse.md)")
    add_config_options(p, "--cover-resolution")
    p.add_argument("--quick", action="store_true",
                   help="coarse ground truth (2 cm), fewer covering voxels, budgets and draws, for a fast look")


def _greenhouse(args) -> int:
    from tqdm.auto import tqdm

    config = row_config(args)
    if args.dataset is not None:
        cases = [c for c in dataset_cases(args.dataset) if c.room == args.room]
        if not cases:
            raise TpvpError(f"{args.dataset}: no two sessions of {args.room} to pair")
        if not 0 <= args.pair < len(cases):
            raise TpvpError(f"--pair {args.pair}: {args.dataset} has pairs 0..{len(cases) - 1} of {args.room}")
        case = cases[args.pair]
    else:
        if not 0 <= args.pair <= 3:
            raise TpvpError(f"--pair {args.pair}: a generated row has sessions 0..4, pairs 0..3")
        case = RowCase(args.room, args.pair, args.seed, reference=args.reference or "handheld")
    print(f"{case.name}: configuration {config.name!r}, covering voxel {100 * config.selection.cover_resolution:g} cm, "
          f"ground truth {100 * config.gt_resolution:g} cm")
    stages = ["scene and oracle", "registration", "inflation", "look-at targets", "visibility", "view selection",
              "path", "execution", "outputs"]
    inputs = case.files
    with staged_folder(args.output, inputs=inputs) as stage, drawing_pool() as pool, \
            tqdm(total=len(stages), desc="tpvp greenhouse", unit="stage", leave=False, disable=None) as bar:
        def step(stage_name):
            bar.update(1)
            bar.set_postfix_str(stage_name)

        bar.set_postfix_str(stages[0])
        previous, current = case.load()
        scene = build_row_scene(previous, current, config, names=(f"{case.name} (previous)", f"{case.name} (current)"),
                                cache_dir=args.cache, date=case.date)
        result = run_row_case(scene, config, progress=step)
        step("outputs")
        write_row_case_outputs(stage.folder, scene, result, config, case.name, pool=pool)
    rows = [("views (15 passive included)", f"{result.n_views}"),
            ("coverage of the oracle set", f"{100 * result.coverage:.2f} % (passive sweep alone "
                                           f"{100 * result.coverage_captured:.2f} %)"),
            ("path length", f"{result.path_length:.2f} m (passive sweep {scene.room.passive_cost:.2f} m included; "
                            f"band path gap to its lower bound {100 * result.path.gap:.2f} %)"),
            ("Chamfer transferred vs coarse", f"{1e3 * result.transfer.alignment.chamfer_before:.2f} -> "
                                              f"{1e3 * result.transfer.alignment.chamfer_after:.2f} mm"),
            ("view selection", f"{len(result.planned_views)} of {len(result.candidates)} candidates, "
                               f"optimal={result.selection.optimal}"),
            ("time: oracle", f"{scene.timings['oracle']:.1f} s" + (" (from the cache)" if scene.oracle_cached else "")),
            ("time: registration / planning", f"{result.timings['registration']:.2f} s / {result.timings['planning']:.2f} s")]
    print_rows(rows, stage.destination, "results.json/.csv, plan.csv, plan.json, config.yaml, provenance.json, "
                                        "plan.png, recording.rrd")
    print_warnings(result.warnings)
    return 0


def greenhouse_arguments(p) -> None:
    row_options(p, "outputs/greenhouse")
    add_config_options(p, "--room")
    p.add_argument("--pair", type=int, default=0,
                   help="which consecutive pair: sessions K -> K+1 (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the generated row (default: %(default)s)")
    p.add_argument("--cache", default=None,
                   help="folder of cached oracles (default: $TPVP_CACHE_DIR or ~/.cache/tpvp)")
    p.set_defaults(func=_greenhouse)
