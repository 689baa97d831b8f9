"""``tpvp render``: the bundled real tomato seen from every view."""

from __future__ import annotations

import json
from pathlib import Path

from tpvp.io import atomic_write_text
from tpvp.io.publish import staged_folder
from tpvp.simulate.render_demo import RenderDemoConfig, run_render_demo


def _render(args) -> int:
    with staged_folder(args.output) as stage:
        table, summary = run_render_demo(RenderDemoConfig(view_space=args.view_space, model=args.model),
                                         output=stage.folder)
        summary["depth_images"] = [Path(p).name for p in summary.get("depth_images", [])]
        atomic_write_text(stage.folder / "coverage_per_view.csv", table.to_csv(index=False))
        atomic_write_text(stage.folder / "summary.json", json.dumps(summary, indent=2) + "\n")
    out = stage.destination
    print(f"bundled real tomato ({summary['sample']}): {summary['plant_voxels']} plant voxels at 2 mm, "
          f"{summary['table_voxels']} table voxels")
    print(f"oracle visible set over {summary['views']} {args.view_space} views: "
          f"{summary['oracle_voxels']} voxels ({args.model} sensor, "
          f"{summary['render_ms_per_view']:.1f} ms/view)")
    print(table[["view", "seen_voxels", "new_voxels", "coverage"]].to_string(
        index=False, formatters={"coverage": "{:.2%}".format}))
    names = ["coverage_per_view.csv", "summary.json", *summary["depth_images"]]
    print(f"wrote {out}/ ({', '.join(names)})")
    return 0


def render_arguments(p) -> None:
    p.add_argument("--output", default="outputs/render", help="output folder (default: %(default)s)")
    p.add_argument("--view-space", default="hemisphere", choices=["hemisphere", "sphere"],
                   help="hemisphere (with table) or sphere (no table) (default: %(default)s)")
    p.add_argument("--model", default="reference", choices=["reference", "pixel"],
                   help="sensor model (default: the authors' voxel-driven 'reference')")
    p.set_defaults(func=_render)
