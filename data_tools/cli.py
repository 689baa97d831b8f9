"""``python -m data_tools``: download and clean the public data, prepare new sessions.

Errors the user can fix are printed on one line (exit status 2), never as a traceback; a dataset
being written by another run is refused at once (exit status 3), outputs that could not be written
(disk full, permissions) leave the dataset as it was (exit status 4), and Ctrl-C says whether the
dataset was updated (exit status 130).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from data_tools.capture.formats import FORMATS
from data_tools.capture.fusion import SCALES
from data_tools.kaggle_download import KAGGLE_DATASET
from tpvp.errors import install_warning_format, run_command
from tpvp.errors import TpvpError


def _pheno4d_download(args) -> int:
    from data_tools.pheno4d import download_pheno4d

    url = {"url": args.url} if args.url else {}
    path = download_pheno4d(args.output, sha256=args.sha256, extract=not args.no_extract, **url)
    print(f"Pheno4D ready: {path}")
    return 0


def _pheno4d_prepare(args) -> int:
    from data_tools.pheno4d import Pheno4DConfig, prepare_pheno4d

    config = Pheno4DConfig(largest_side=args.largest_side, gt_resolution=args.gt_resolution, year=args.year)
    table = prepare_pheno4d(args.source, args.output, config, force=args.force)
    where = args.source or "the bundled real samples"
    skipped = table.attrs.get("skipped", [])
    for name, why in skipped[:10]:
        print(f"  skipped {name}: {why}")
    if len(skipped) > 10:
        print(f"  ... and {len(skipped) - 10} more skipped file(s), all listed in {args.output}/NOTICE.md")
    print(f"prepared {len(table)} scan(s) of {table['plant'].nunique()} plant(s) and "
          f"{len(table.attrs.get('pairs', []))} session pair(s) from {where} into {args.output}/ "
          f"(manifest.csv, pairs.csv){f'; skipped {len(skipped)} file(s)' if skipped else ''}")
    return 0


def _helios(args) -> int:
    from data_tools.helios import HeliosConfig, prepare_helios

    config = HeliosConfig(spacing=args.spacing, plants=args.plants, seed=args.seed)
    table = prepare_helios(args.output, args.species, args.ages, config, force=args.force)
    print(f"grew {table['plant'].nunique()} plant(s) of {len(args.species)} species through {len(args.ages)} "
          f"session(s) each: {len(table)} scan(s), {table['points'].min():,}-{table['points'].max():,} points, "
          f"{len(table.attrs.get('pairs', []))} session pair(s), into {args.output}/ (manifest.csv, pairs.csv)")
    return 0


def _greenhouse_download(args) -> int:
    from data_tools.kaggle_download import download_greenhouse

    path = download_greenhouse(args.output, args.dataset, unzip=not args.no_unzip, force=args.force)
    print(f"greenhouse dataset in {path}; next: python -m data_tools greenhouse clean {path}")
    return 0


def _clean_configs(args):
    from data_tools.alignment import IcpConfig
    from data_tools.cleaning import CleanConfig

    return (CleanConfig(voxel_size=args.voxel_size, sor_std_ratio=args.sor_std_ratio),
            IcpConfig(max_correspondence=args.icp_distance))


def _greenhouse_clean(args) -> int:
    from data_tools.greenhouse import clean_greenhouse

    if args.source is None and args.manifest is None:
        raise TpvpError("give the folder of session scans, or --manifest FILE")
    clean, icp = _clean_configs(args)
    table = clean_greenhouse(args.source, args.output, manifest=args.manifest, landmarks=args.landmarks,
                             config_dir=args.config, units=args.units, clean=clean, icp=icp, force=args.force)
    print(table[["site", "date", "points_raw", "points", "alignment", "fitness", "inlier_rmse_m",
                 "rotation_deg", "translation_m"]].to_string(index=False, float_format="{:.4f}".format))
    print(f"wrote {len(table)} session(s) to {args.output}/ (Processed_3D_Model, transforms, manifest.csv)")
    return 0


def _greenhouse_standin(args) -> int:
    from data_tools.greenhouse_standin import write_processed_standin, write_raw_standin

    if args.processed:
        folder = write_processed_standin(args.output, args.room, args.seed, args.sessions)
    else:
        folder = write_raw_standin(args.output, args.room, args.seed, args.sessions).folder
    print(f"wrote generated {args.room} sessions to {folder}")
    return 0


def _prepare_session(args) -> int:
    from data_tools.greenhouse import check_site, parse_date
    from data_tools.sessions import prepare_session

    site, date = check_site(args.site, "--site"), parse_date(args.date, "--date")  # errors name the option
    clean, icp = _clean_configs(args)
    row = prepare_session(args.dataset, site, date, args.scan, landmarks=args.landmarks,
                          units=args.units, clean=clean, icp=icp, force=args.force)
    print(f"{row['site']} {row['date']}: {row['points_raw']} -> {row['points']} points, alignment "
          f"{row['alignment']} (fitness {row['fitness']:.3f}, RMSE {1000 * row['inlier_rmse_m']:.1f} mm, "
          f"{row['rotation_deg']:.2f} deg, {row['translation_m']:.3f} m); wrote {args.dataset}/{row['file']}")
    return 0


def _capture_fuse(args) -> int:
    from contextlib import ExitStack
    from dataclasses import replace

    from data_tools.capture.formats import detect_format, read_capture
    from data_tools.capture.fusion import PHONE_LAYOUTS, corrections_csv, corrections_path, fuse_capture, fusion_config
    from tpvp.io import atomic_write_text, write_point_cloud
    from tpvp.io.publish import staged_file

    config = fusion_config(args.scale, voxel_size=args.voxel_size, truncation=args.truncation,
                           max_depth=args.max_depth, min_confidence=args.min_confidence, spacing=args.spacing,
                           support=args.support)
    corrections = corrections_path(args.output)
    # Locked from the start, as a folder output is: a second run on the same file is refused at once.
    # The corrections file is locked with the cloud and follows the same --force rule.
    with ExitStack() as outputs:
        staged = outputs.enter_context(staged_file(args.output, inputs=[args.source], force=args.force))
        # Default: on for a phone's plant orbit; off for a row, where the stand-in's walk measured worse
        # refined than as reported (docs/data_tools.md), and for a depth folder (poses not ARKit's).
        refine = (args.refine_poses if args.refine_poses is not None
                  else args.scale == "plant" and (args.format or detect_format(args.source)) in PHONE_LAYOUTS)
        config = replace(config, refine_poses=refine)
        staged_corrections = (outputs.enter_context(staged_file(corrections, inputs=[args.source], force=args.force,
                                                                what="corrections file")) if refine else None)
        capture = read_capture(args.source, args.format, args.depth_scale)
        print(f"{capture.folder}: {len(capture.frames)} frames ({capture.format}); fusing at "
              f"{1000 * config.voxel_size:g} mm voxels, truncation {1000 * config.truncation:g} mm, depth up to "
              f"{config.max_depth:g} m (--scale {args.scale}); poses {'refined' if refine else 'as reported'}")
        fused = fuse_capture(capture, config)
        write_point_cloud(staged, fused.points, colors=fused.colours)
        if staged_corrections is not None:
            atomic_write_text(staged_corrections, corrections_csv(fused.corrections))
    print(f"wrote {args.output}: {len(fused.points):,} surface points with colours (metres, the capture's world frame)")
    if refine:
        largest = fused.largest_correction()
        kept = sum(c.status.startswith("kept") for c in fused.corrections)
        print(f"wrote {corrections}: every frame's pose correction; the largest: frame {largest.name}, "
              f"{largest.translation_mm:.1f} mm and {largest.rotation_deg:.2f} deg; {kept} of "
              f"{len(fused.corrections) - 1} frames kept their carried correction (a poor or no gain fit)")
    return 0


def _capture_standin(args) -> int:
    from data_tools.capture.phone_standin import plant_scene, row_scene, write_standin

    scene = (plant_scene(args.species, args.seed, args.size, args.frames) if args.scene == "plant"
             else row_scene(args.room, args.seed))
    seed = args.seed if args.noise_seed is None else args.noise_seed
    folder = write_standin(args.output, args.format, scene, force=args.force, noise=args.noise, noise_seed=seed)
    print(f"wrote a {args.format} capture of a generated {args.species if args.scene == 'plant' else args.room} "
          f"({len(scene.positions)} frames, noise {args.noise}) and its truth.ply to {folder}; next: "
          f"python -m data_tools capture fuse "
          f"{folder} --scale {args.scene} --output cloud.ply")
    return 0


def _cleaning_options(p):
    p.add_argument("--units", default="m", choices=["m", "mm", "auto"],
                   help="units of the scans (default: %(default)s; Polycam exports metres)")
    p.add_argument("--voxel-size", type=float, default=0.005, help="downsampling voxel, m (default: %(default)s)")
    p.add_argument("--sor-std-ratio", type=float, default=2.0,
                   help="statistical outlier removal cut, standard deviations (default: %(default)s)")
    p.add_argument("--icp-distance", type=float, default=0.05,
                   help="ICP correspondence distance, m (default: %(default)s)")
    p.add_argument("--force", action="store_true", help="replace existing output")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m data_tools", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    pheno = sub.add_parser("pheno4d", help="the Pheno4D single-plant scans").add_subparsers(dest="action", required=True)
    p = pheno.add_parser("download", help="download (resumable) and unpack the official Pheno4D archive")
    p.add_argument("--output", default="data/raw", help="download folder (default: %(default)s)")
    p.add_argument("--url", default=None, help="archive URL (default: the official Pheno4D.zip)")
    p.add_argument("--sha256", default=None, help="expected SHA-256 of the archive, if you have one")
    p.add_argument("--no-extract", action="store_true", help="keep the zip only (prepare reads it directly)")
    p.set_defaults(func=_pheno4d_download)
    p = pheno.add_parser("prepare", help="convert every plant/day into a clean dataset (manifest, pairs, 2 mm grids)")
    p.add_argument("source", nargs="?", default=None,
                   help="extracted Pheno4D folder or Pheno4D.zip (default: the bundled real samples)")
    p.add_argument("--output", default="data/pheno4d", help="dataset folder (default: %(default)s)")
    p.add_argument("--largest-side", type=float, default=0.24, help="normalised largest side, m (default: %(default)s)")
    p.add_argument("--gt-resolution", type=float, default=0.002, help="ground-truth voxel, m (default: %(default)s)")
    p.add_argument("--year", type=int, default=2020, help="year of the MMDD dates in the file names (default: %(default)s)")
    p.add_argument("--force", action="store_true", help="replace an existing dataset")
    p.set_defaults(func=_pheno4d_prepare)

    p = sub.add_parser("helios", help="grow plants with Helios (pyhelios3d) into a prepared dataset with organ labels",
                       description="Grow each species with Helios' PlantArchitecture from a seed through the given "
                                   "ages (the first builds the plant, later ones advance the same plant), sample each "
                                   "session's surface into points with organ labels, and write the layout of "
                                   "pheno4d prepare. Needs the optional package pyhelios3d.")
    p.add_argument("--species", nargs="+", required=True,
                   help="Helios plant models, e.g. tomato bean maize (an unknown name lists the available ones)")
    p.add_argument("--ages", nargs="+", type=int, required=True,
                   help="session ages in days, strictly increasing (dated from the sowing day 2025-01-01)")
    p.add_argument("--output", type=Path, required=True, help="dataset folder")
    p.add_argument("--plants", type=int, default=1,
                   help="plants per species, each from its own seed (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0,
                   help="random seed of the plants and the sampling (default: %(default)s)")
    p.add_argument("--spacing", type=float, default=0.00125,
                   help="surface sampling: one point per spacing squared on average, m (default: %(default)s)")
    p.add_argument("--force", action="store_true", help="replace an existing dataset")
    p.set_defaults(func=_helios)

    green = sub.add_parser("greenhouse", help="the greenhouse multi-session row dataset").add_subparsers(dest="action", required=True)
    p = green.add_parser("download", help="download the dataset from Kaggle (needs an API token)")
    p.add_argument("--output", default="data/greenhouse_raw", help="download folder (default: %(default)s)")
    p.add_argument("--dataset", default=KAGGLE_DATASET, help="Kaggle dataset (default: %(default)s)")
    p.add_argument("--no-unzip", action="store_true", help="keep the downloaded zip as it is (default: unzip it)")
    p.add_argument("--force", action="store_true", help="download again even if complete")
    p.set_defaults(func=_greenhouse_download)
    p = green.add_parser("clean", help="crop, remove supports and outliers, downsample, align every session to day one")
    p.add_argument("source", nargs="?", default=None, help="folder of per-session scans (names hold room and date)")
    p.add_argument("--manifest", type=Path, default=None, help="CSV listing site,date,file[,landmarks] instead")
    p.add_argument("--landmarks", type=Path, default=None, help="folder of landmark files named like the sessions")
    p.add_argument("--config", type=Path, default=None,
                   help="folder of <site>_bbx_config.yaml box files (default: the bundled room1/room4)")
    p.add_argument("--output", default="data/greenhouse", help="dataset folder (default: %(default)s)")
    _cleaning_options(p)
    p.set_defaults(func=_greenhouse_clean)
    p = green.add_parser("standin", help="write generated rows in the dataset's layouts (offline stand-in)")
    p.add_argument("--output", default="data/greenhouse_standin", help="output folder (default: %(default)s)")
    p.add_argument("--room", default="room1", choices=["room1", "room4"],
                   help="greenhouse room whose boxes the generated row fills (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the generated row (default: %(default)s)")
    p.add_argument("--sessions", type=int, default=5, help="number of sessions 1..5 (default: %(default)s)")
    p.add_argument("--processed", action="store_true",
                   help="write processed models (Processed_3D_Model) instead of raw captures with landmarks")
    p.set_defaults(func=_greenhouse_standin)

    capture = sub.add_parser("capture", help="a phone's or depth camera's capture").add_subparsers(dest="action", required=True)
    p = capture.add_parser("fuse", help="fuse a capture's depth frames into one coloured cloud (TSDF)")
    p.add_argument("source", type=Path, help="the capture folder: nerfstudio transforms.json, Polycam raw data, or a "
                                             "depth folder (depth/, poses/, intrinsics.yaml)")
    p.add_argument("--output", type=Path, required=True, help="the cloud to write (.ply, with colours)")
    p.add_argument("--format", default=None, choices=FORMATS, help="the capture's layout (default: detected)")
    p.add_argument("--scale", default="plant", choices=list(SCALES),
                   help="defaults for a single plant (5 mm voxels, depth up to 1.5 m) or a greenhouse row (1 cm, "
                        "3 m) (default: %(default)s)")
    p.add_argument("--voxel-size", type=float, default=None, help="TSDF voxel, m (default: the scale's)")
    p.add_argument("--truncation", type=float, default=None, help="TSDF truncation, m (default: the scale's, 2 voxels)")
    p.add_argument("--max-depth", type=float, default=None, help="depth beyond this is background, m")
    p.add_argument("--min-confidence", type=int, default=None, choices=[0, 1, 2],
                   help="drop depth below this ARKit confidence level (default: 1, medium)")
    p.add_argument("--spacing", type=float, default=None,
                   help="sample the fused surface mesh this far apart, m (default: the scale's, 1.25 mm / 5 mm)")
    p.add_argument("--support", type=float, default=None,
                   help="keep a surface point where a frame measured it within this, m (default: the scale's)")
    p.add_argument("--depth-scale", type=float, default=None,
                   help="metres per depth unit (default: 0.001 for 16-bit PNG, 1 for .npy, or the intrinsics')")
    p.add_argument("--refine-poses", action=argparse.BooleanOptionalAction, default=None,
                   help="align each frame to the model fused so far before integrating it (point-to-plane ICP) "
                        "and write the corrections to NAME.corrections.csv beside the output (default: on for the "
                        "phone layouts nerfstudio and polycam at --scale plant; off for a row and a depth folder)")
    p.add_argument("--force", action="store_true", help="replace an existing output (and its corrections file)")
    p.set_defaults(func=_capture_fuse)
    p = capture.add_parser("standin", help="write a capture of a generated plant or row (check an import offline)")
    p.add_argument("--format", required=True, choices=FORMATS, help="the layout to write")
    p.add_argument("--output", type=Path, required=True, help="the capture folder to write")
    p.add_argument("--scene", default="plant", choices=["plant", "row"],
                   help="an orbit around a plant, or the handheld walk along a row (default: %(default)s)")
    p.add_argument("--species", default="tomato", choices=["tomato", "maize"], help="the plant (default: %(default)s)")
    p.add_argument("--size", type=float, default=0.4, help="the plant's largest side, m (default: %(default)s)")
    p.add_argument("--frames", type=int, default=120, help="frames of the orbit (default: %(default)s)")
    p.add_argument("--room", default="room1", choices=["room1", "room4"], help="the row's room (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the generated scene (default: %(default)s)")
    p.add_argument("--noise", default="ideal",
                   help="sensor noise profile of the depth and poses: ideal, arm-rgbd, phone-lidar "
                        "(docs/sensor.md#sensor-noise; default: %(default)s, exact)")
    p.add_argument("--noise-seed", type=int, default=None,
                   help="seed of the noise: frame i draws from (seed, i) (default: --seed)")
    p.add_argument("--force", action="store_true", help="replace an existing stand-in folder")
    p.set_defaults(func=_capture_standin)

    p = sub.add_parser("prepare-session", help="add a new scan of a site to a dataset (crop, clean, align)")
    p.add_argument("--site", required=True, help="site name, e.g. room1 (letters, digits, '-', '_')")
    p.add_argument("--date", required=True, help="session date, YYYY-MM-DD")
    p.add_argument("--scan", required=True, type=Path, help="the new scan (ply/pcd/xyz/obj)")
    p.add_argument("--landmarks", type=Path, default=None,
                   help="CSV of picked pairs source_x..z,target_x..z (scan -> reference day)")
    p.add_argument("--dataset", default="data/greenhouse", help="dataset folder (default: %(default)s)")
    _cleaning_options(p)
    p.set_defaults(func=_prepare_session)
    return parser


def main(argv=None) -> int:
    install_warning_format("data_tools")
    args = build_parser().parse_args(argv)
    name = " ".join(x for x in (args.command, getattr(args, "action", None)) if x)
    return run_command(args, f"data_tools {name}")


if __name__ == "__main__":
    sys.exit(main())
