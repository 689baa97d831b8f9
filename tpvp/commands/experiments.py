"""``tpvp experiments plants|rows``: the paper's experiments, their tables and figures."""

from __future__ import annotations

from pathlib import Path

from tpvp.cli_common import OPTION, case_options, config_overrides, resolved_config
from tpvp.config import PlantConfig
from tpvp.config_loading import flatten_keys, to_dict, with_overrides
from tpvp.errors import ConfigError, TpvpError
from tpvp.commands.rows import row_config, row_options
from tpvp.experiments import plants as plant_experiments
from tpvp.experiments import rows as row_experiments
from tpvp.experiments import season
from tpvp.experiments.results import markdown, write_results
from tpvp.scene.boxes import ROOMS
from tpvp.sensor.noise import NOISE_PROFILES
from tpvp.simulate.row_cases import default_row_cases


def _experiments_plants(args) -> int:
    config = resolved_config(args)
    cases = plant_experiments.default_cases(args.quick, args.dataset, args.plants, args.pairs, args.paper_subset,
                                            tuple(args.view_spaces), tuple(args.rotations), tuple(args.initial_views))
    methods = args.methods or list(plant_experiments.PLANT_METHODS.defaults())
    where = f"the Dask cluster {args.scheduler}" if args.scheduler else f"{args.workers} local worker(s)"
    print(f"{len(cases)} cases x {len(methods)} methods on {where}; cache {args.cache}")
    raw = plant_experiments.run_experiments(cases, methods, config, cache_dir=args.cache, workers=args.workers,
                                            scheduler=args.scheduler)
    comparison = plant_experiments.comparison_case(cases) if args.comparison else None
    return _publish(plant_experiments.PLANT_EXPERIMENTS, args.output, raw, config, "table1_coverage_effort",
                    f"paper_values.csv, figures/{', comparison/' if comparison else ''}", comparison=comparison)


def _experiments_rows(args) -> int:
    config = row_config(args)
    cases = default_row_cases(args.quick, args.dataset, tuple(args.rooms), references=args.reference or ["handheld"])
    methods = args.methods or list(row_experiments.ALL_METHODS)
    where = f"the Dask cluster {args.scheduler}" if args.scheduler else f"{args.workers} local worker(s)"
    print(f"{len(cases)} cases x {len(methods)} methods on {where}; cache {args.cache}")
    raw = row_experiments.run_row_experiments(cases, methods, config, cache_dir=args.cache, workers=args.workers,
                                              scheduler=args.scheduler)
    return _publish(row_experiments.ROW_EXPERIMENTS, args.output, raw, config, "table6_coverage_effort",
                    "paper_values.csv, figures/")


#: Options of the plants' season (their defaults) and of the rows' (``--rows``): given to the other, refused.
PLANT_SEASON_ONLY = {"--species": list(season.SPECIES), "--view-spaces": list(season.VIEW_SPACES),
                     "--replan-after": list(season.REPLAN_AFTER), "--dataset": None, "--plants": None,
                     "--frame": season.FRAME, "--noise": None}
ROW_SEASON_ONLY = {"--rooms": list(season.ROOMS)}
#: Keys the plants' season sets per case, each from its own option (a sweep over its values).
SEASON_CASE_KEYS = {"view_space": "--view-spaces", "selection.replan_after": "--replan-after", "scene.frame": "--frame"}


def _given(args, options: dict) -> str | None:
    """The first of ``options`` (flag -> default) that ``args`` gives another value."""
    dests = {"--replan-after": "replan_after_values"}
    return next((flag for flag, default in options.items()
                 if getattr(args, dests.get(flag, flag[2:].replace("-", "_"))) != default), None)


def season_setup(args):
    """The season's base configuration and cases, from the options alone (nothing is run). The
    plants' target is the configuration's ``selection.coverage_target`` where one is given
    (``--coverage-target``, ``--set``, a ``--config`` file that changes it), else the season's
    0.98; a key the cases set per case, given by ``--config`` or ``--set``, is refused."""
    if args.rows:  # the paper-row configuration, unless --config names another row one
        if flag := _given(args, PLANT_SEASON_ONLY):
            raise ConfigError(f"{flag} applies to the plants' season; --rows runs the greenhouse rows' season "
                              f"(--rooms, --seeds, --sessions)")
        config = resolved_config(args, "paper-row" if args.config == "paper" else args.config)
        if config.setting != "row":
            raise TpvpError(f"--rows plans rows; configuration {config.name!r} is a {config.setting} one")
        return config, season.row_season_cases(args.quick, tuple(args.rooms), tuple(args.seeds),
                                               args.sessions or season.ROW_SESSIONS)
    if flag := _given(args, ROW_SEASON_ONLY):
        raise ConfigError(f"{flag} applies to the rows' season (--rows); without it the season is of plants")
    config = resolved_config(args)
    if args.noise is not None:  # one profile for every arm's captures
        if "sensor.noise" in config_overrides(args) and config.sensor.noise != args.noise:
            raise ConfigError(f"--noise {args.noise} and sensor.noise={config.sensor.noise!r} (--set) disagree; "
                              f"give one")
        config = with_overrides(config, {"sensor.noise": args.noise})
    if config.setting != "plant":
        raise TpvpError(f"the plants' season plans plants; configuration {config.name!r} is a {config.setting} one "
                        f"(--rows for the rows' season)")
    given, default = config_overrides(args), flatten_keys(to_dict(PlantConfig()))
    values = flatten_keys(to_dict(config))
    for key, flag in SEASON_CASE_KEYS.items():  # a value the option gives anyway (realistic's frame) is no conflict
        if (key in given or values[key] != default[key]) and values[key] != getattr(args, flag[2:], None):
            raise ConfigError(f"{key}={values[key]!r} (--config or --set): the season sets it per case from {flag}; "
                              f"give {flag} instead")
    key = "selection.coverage_target"
    target = values[key] if key in given or values[key] != default[key] else season.COVERAGE_TARGET
    if args.dataset is not None:
        return config, season.dataset_season_cases(args.dataset, args.plants, args.quick, tuple(args.view_spaces),
                                                   target, tuple(args.replan_after_values), args.frame)
    return config, season.season_cases(args.quick, tuple(args.species), tuple(args.seeds),
                                       args.sessions or season.SESSIONS, tuple(args.view_spaces), target,
                                       tuple(args.replan_after_values), args.frame)


def _experiments_season(args) -> int:
    config, cases = season_setup(args)
    if args.rows:
        arms = args.arms or list(season.ROW_SEASON_ARMS.defaults())
        print(f"{len(cases)} row(s) x {len(arms)} arm(s), {cases[0].sessions} sessions each; cache {args.cache}")
        raw = season.run_row_season_experiments(cases, arms, config, cache_dir=args.cache, workers=args.workers)
        return _publish(season.ROW_SEASON_EXPERIMENTS, args.output, raw, config, "season_totals", "figures/season.png")
    target = cases[0].coverage_target
    arms = args.arms or list(season.SEASON_ARMS.defaults())
    print(f"{len(cases)} plant(s) x {len(arms)} arm(s), {cases[0].sessions} sessions each, coverage target {target:g}; "
          f"cache {args.cache}")
    raw = season.run_season_experiments(cases, arms, config, cache_dir=args.cache, workers=args.workers)
    return _publish(season.SEASON_EXPERIMENTS, args.output, raw, config, "season_totals", "figures/season.png")


def _publish(experiment, output, raw, config, headline: str, more: str, **options) -> int:
    """Write the experiment's results folder, print its ``headline`` table and what was written."""
    written = write_results(experiment, output, raw, config, **options)
    print(markdown(written[headline]))
    print(f"wrote {Path(output).absolute()}/ (raw_cases.csv, {', '.join(f'{n}.csv/.md' for n in written)}, {more})")
    return 0


def experiments_arguments(experiments) -> None:
    which = experiments.add_subparsers(dest="experiment", required=True)
    plant = which.add_parser("plants", help="individual plants: Tables I-IV, every baseline, the exact optimum")
    case_options(plant, "outputs/experiments/plants", case_options=False)
    plant.add_argument("--dataset", type=Path, default=None,
                       help="a folder written by `python -m data_tools pheno4d prepare` or `helios` (default: generated "
                            "tomato and maize pairs plus the bundled real pair, offline)")
    plant.add_argument("--plants", nargs="+", default=None, help="only these plants of the dataset (e.g. Tomato01)")
    plant.add_argument("--pairs", nargs="+", type=int, default=None, help="only these rows of the dataset's pairs.csv")
    plant.add_argument("--paper-subset", action="store_true", help="plants 1-3 of each species, one pair each")
    plant.add_argument("--view-spaces", nargs="+", default=["hemisphere", "sphere"], help="(default: %(default)s)")
    plant.add_argument("--rotations", nargs="+", type=float, default=[0.0, 45.0], help="degrees about +Z (default: %(default)s)")
    plant.add_argument("--initial-views", nargs="+", type=int, default=[17, 8, 21], help="(default: %(default)s)")
    plant.add_argument("--methods", nargs="+", default=None,
                       help=f"methods to run ({plant_experiments.PLANT_METHODS.describe()})")
    plant.add_argument("--quick", action="store_true", help="a few cases: one tomato and one maize pair, rotation 0, view 17")
    plant.add_argument("--workers", type=int, default=2, help="parallel processes (default: %(default)s)")
    plant.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run the tasks on a Dask cluster, e.g. tcp://10.0.0.5:8786 (the cache folder must be "
                            "shared with its workers; default: local processes)")
    plant.add_argument("--no-comparison", dest="comparison", action="store_false",
                       help="skip the comparison figure (GMC, Ours and the exact optimum on the first sphere case, "
                            "with a rerun recording; about 30 s)")
    plant.add_argument("--cache", default="outputs/cache/plants",
                       help="cache folder of per-task rows; an interrupted run resumes (default: %(default)s)")
    plant.set_defaults(func=_experiments_plants)
    rows = which.add_parser("rows", help="greenhouse rows: Tables V-VI (Ours, random prior ladder, upper limits)")
    row_options(rows, "outputs/experiments/rows", several_references=True)
    rows.add_argument("--rooms", nargs="+", default=list(ROOMS), choices=ROOMS, help="(default: %(default)s)")
    rows.add_argument("--methods", nargs="+", default=None,
                      help=f"methods to run (default: {', '.join(row_experiments.ALL_METHODS)}; also: "
                           f"{', '.join(sorted(set(row_experiments.ROW_METHODS.names()) - set(row_experiments.ALL_METHODS)))})")
    rows.add_argument("--workers", type=int, default=2, help="parallel processes (default: %(default)s)")
    rows.add_argument("--scheduler", default=None, metavar="ADDRESS",
                      help="run the tasks on a Dask cluster, e.g. tcp://10.0.0.5:8786 (default: local processes)")
    rows.add_argument("--cache", default="outputs/cache/rows",
                      help="cache folder of per-task rows and the oracles (default: %(default)s)")
    rows.set_defaults(func=_experiments_rows)
    seasons = which.add_parser("season", help="a season of generated plants: each session planned from the truth or "
                                             "from the last session's own reconstruction (closed loop)")
    case_options(seasons, "outputs/experiments/season", case_options=False)
    seasons.add_argument("--species", nargs="+", default=list(season.SPECIES), choices=season.SPECIES,
                         help="(default: %(default)s)")
    seasons.add_argument("--seeds", nargs="+", type=int, default=list(season.SEEDS),
                         help="generated plants (default: %(default)s)")
    seasons.add_argument("--sessions", type=int, default=None,
                         help=f"scans of each plant, two days apart, or of each row (default: {season.SESSIONS} for a "
                              f"plant, {season.ROW_SESSIONS} for a row)")
    seasons.add_argument("--dataset", type=Path, default=None,
                         help="a folder written by `python -m data_tools pheno4d prepare` or `helios`: one season per plant, its "
                              "scans in date order (default: generated plants)")
    seasons.add_argument("--plants", nargs="+", default=None, help="only these plants of the dataset (e.g. Tomato01)")
    seasons.add_argument("--rows", action="store_true",
                         help="the greenhouse rows' season instead: generated rows of --rooms, each session planned at "
                              "4 cm (the paper-row configuration); --species, --view-spaces and --replan-after do not "
                              "apply")
    seasons.add_argument("--rooms", nargs="+", default=list(season.ROOMS), help="(with --rows; default: %(default)s)")
    seasons.add_argument("--view-spaces", nargs="+", default=list(season.VIEW_SPACES), help="(default: %(default)s)")
    OPTION["--replan-after"].add_to(  # a sweep: several K, the season once per value (selection.replan_after)
        seasons, nargs="+", dest="replan_after_values", default=list(season.REPLAN_AFTER),
        help="re-plan each session's plan from its captures after every K planned views; several "
             "values run the season once per value, 0 = plan once (default: %(default)s)")
    seasons.add_argument("--frame", default=season.FRAME, choices=("previous", "current"),
                         help="each session's planning frame: from its prior and first capture, as a robot knows it, "
                              "or fitted to today's full scan (the paper's tables) (default: %(default)s)")
    seasons.add_argument("--noise", default=None, choices=NOISE_PROFILES.names(), metavar="PROFILE",
                         help=f"the sensor of every arm's captures, the own arm's fused prior included: "
                              f"{', '.join(NOISE_PROFILES.names())} (default: the configuration's sensor.noise)")
    seasons.add_argument("--arms", nargs="+", default=None,
                         help=f"priors to plan from ({season.SEASON_ARMS.describe()})")
    seasons.add_argument("--quick", action="store_true",
                         help=f"one tomato, {season.QUICK['sessions']} sessions, in each view space and "
                              f"re-planning asked (about 15 s per view space and re-planning)")
    seasons.add_argument("--workers", type=int, default=2, help="parallel processes (default: %(default)s)")
    seasons.add_argument("--cache", default="outputs/cache/season",
                         help="cache folder of per-(plant, arm) rows; an interrupted run resumes (default: %(default)s)")
    seasons.set_defaults(func=_experiments_season)
