"""Command line: ``tpvp demo`` and friends. A thin layer over the library.

Errors the user can fix (:class:`tpvp.errors.TpvpError`) are printed on one line, exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tpvp.errors import TpvpError


def _demo(args) -> int:
    from tpvp.experiments.render_demo import RenderDemoConfig, run_render_demo
    from tpvp.io import atomic_write_text

    table, summary = run_render_demo(RenderDemoConfig(view_space=args.view_space, model=args.model))
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "coverage_per_view.csv", table.to_csv(index=False))
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    print(f"bundled real tomato ({summary['sample']}): {summary['plant_voxels']} plant voxels at 2 mm, "
          f"{summary['table_voxels']} table voxels")
    print(f"oracle visible set over {summary['views']} {args.view_space} views: "
          f"{summary['oracle_voxels']} voxels ({args.model} sensor, "
          f"{summary['render_ms_per_view']:.1f} ms/view)")
    print(table[["view", "seen_voxels", "new_voxels", "coverage"]].to_string(
        index=False, formatters={"coverage": "{:.2%}".format}))
    print(f"wrote {out / 'coverage_per_view.csv'} and {out / 'summary.json'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tpvp", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="render the bundled real tomato and report coverage per view")
    demo.add_argument("--output", default="outputs/demo", help="output folder (default: %(default)s)")
    demo.add_argument("--view-space", default="hemisphere", choices=["hemisphere", "sphere"])
    demo.add_argument("--model", default="reference", choices=["reference", "pixel"],
                      help="sensor model (default: the authors' voxel-driven 'reference')")
    demo.set_defaults(func=_demo)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except TpvpError as exc:
        print(f"tpvp {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
