"""Interactive 3D views (plotly) of a plant or a row, its candidate views, the plan and its path,
and the covered and missed voxels. Plotly, not rerun's notebook viewer: a plotly figure is a few
hundred kB of JSON plus plotly.js (4.6 MB, embedded once), renders offline in JupyterLab, in
nbconvert's HTML copy and on the static site, and needs no kernel or widget state; rerun's
viewer is a WebAssembly app of several tens of MB per page. The rerun recordings (``.rrd``)
stay the tool for looking at a whole run."""

from __future__ import annotations

import numpy as np

_MAX_POINTS = 15_000  # per cloud: keeps a notebook's HTML copy light


def _subsample(points, limit=_MAX_POINTS, *arrays):
    points = np.asarray(points, float).reshape(-1, 3)
    if len(points) <= limit:
        return (points, *arrays)
    keep = np.sort(np.random.default_rng(0).choice(len(points), limit, replace=False))
    return (points[keep], *(np.asarray(a)[keep] for a in arrays))


def _points(name, points, colour, size=1.5, opacity=0.8, text=None):
    import plotly.graph_objects as go

    points, = _subsample(points)
    return go.Scatter3d(x=points[:, 0], y=points[:, 1], z=points[:, 2], mode="markers", name=name,
                        marker={"size": size, "color": colour, "opacity": opacity}, hovertext=text,
                        hoverinfo="name" if text is None else "text")


def scene_3d(clouds: dict | None = None, candidates=None, executed=None, selected=None, path_polyline=None,
             look_ats=None, title: str = "", height: int = 620):
    """A plotly figure: ``clouds`` ``{name: (points, colour)}`` (e.g. the plant, covered voxels in
    blue, missed voxels in red), the candidate view positions (grey), executed warm-up views
    (black), ``selected`` views numbered in execution order (red, with a line to each view's
    ``look_ats`` point when given) and the path (purple)."""
    import plotly.graph_objects as go

    traces = []
    for name, (points, colour) in (clouds or {}).items():
        if len(points):
            traces.append(_points(name, points, colour))
    if candidates is not None and len(candidates):
        traces.append(_points("candidate views", candidates, "lightgray", size=2.5, opacity=0.6))
    if executed is not None and len(executed):
        traces.append(_points("executed (initial, warm-up)", executed, "black", size=5, opacity=1.0))
    if selected is not None and len(selected):
        selected = np.asarray(selected, float).reshape(-1, 3)
        traces.append(go.Scatter3d(x=selected[:, 0], y=selected[:, 1], z=selected[:, 2], mode="markers+text",
                                   name="planned views (execution order)", text=[str(i + 1) for i in range(len(selected))],
                                   textfont={"size": 9, "color": "darkred"},
                                   marker={"size": 4.5, "color": "crimson", "symbol": "diamond"}))
        if look_ats is not None and len(look_ats):
            rays = np.full((3 * len(selected), 3), np.nan)
            rays[0::3], rays[1::3] = selected, np.asarray(look_ats, float).reshape(-1, 3)
            traces.append(go.Scatter3d(x=rays[:, 0], y=rays[:, 1], z=rays[:, 2], mode="lines", name="viewing directions",
                                       line={"color": "salmon", "width": 1.5}, hoverinfo="skip"))
    if path_polyline is not None and len(path_polyline) > 1:
        path = np.asarray(path_polyline, float).reshape(-1, 3)
        traces.append(go.Scatter3d(x=path[:, 0], y=path[:, 1], z=path[:, 2], mode="lines", name="path",
                                   line={"color": "purple", "width": 4}))
    figure = go.Figure(traces)
    figure.update_layout(title=title, height=height, margin={"l": 0, "r": 0, "t": 40 if title else 10, "b": 0},
                         legend={"itemsizing": "constant", "x": 0.0, "y": 1.0},
                         scene={"aspectmode": "data", "xaxis_title": "x (m)", "yaxis_title": "y (m)",
                                "zaxis_title": "z (m)"})
    return figure
