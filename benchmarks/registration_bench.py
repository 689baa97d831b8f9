"""Time embedded-deformation registration (paper settings) on real-size plant pairs.

(a) the bundled real tomato: P = 03-05, Q = 03-06 voxelised at 2 mm (a stand-in for the coarse
    reconstruction; timing is what matters here), both normalised into the 03-06 frame (0.24 m);
(b) generated tomato and maize session pairs (ground-truth correspondences), Q = current session
    voxelised at 2 mm.

Per pair: points, graph nodes, seconds, symmetric Chamfer before/after (mm) and, where ground
truth exists, the mean correspondence error before/after (mm), for the analytic-gradient
implementation (``register_embedded_deformation``) and, as the anchor measured in the same process,
the torch-autograd implementation it replaced (``optimise_autograd``; skip it with
``--no-reference``). ``speed-up`` = reference seconds / seconds.
Targets: <= 2 s per pair on 2 cores, Chamfer after within +5 % of the reference's.
Usage: python benchmarks/registration_bench.py [--iterations 300] [--seeds 0 1] [--no-reference]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from tpvp.registration.config import EDConfig
from tpvp.registration.embedded_deformation import register_embedded_deformation
from tpvp.registration.autograd_reference import optimise_autograd
from tpvp.scene import voxels
from tpvp.scene.normalise import normalise_plant
from tpvp.scene.samples import load_sample
from tpvp.synthetic.plants import generate_session_pair

TARGET_SECONDS = 2.0
CHAMFER_TOLERANCE = 1.05  # Chamfer after may exceed the reference's by 5 %


def _real_pair():
    previous, current = load_sample("tomato_0305"), load_sample("tomato_0306")
    P = normalise_plant(previous, reference_points=current).points
    Q = voxels.voxel_centres(normalise_plant(current).points, 0.002)
    return P, Q, None


def _generated_pair(species: str, seed: int):
    pair = generate_session_pair(species, seed)
    cur = pair.current.points
    P = normalise_plant(pair.previous.points, reference_points=cur).points
    current = normalise_plant(cur).points
    Q = voxels.voxel_centres(current, 0.002)
    gt = (pair.correspondence_previous_idx, current[pair.correspondence_current_idx])
    return P, Q, gt


def _correspondence_mm(points, gt):
    if gt is None:
        return float("nan")
    idx, target = gt
    return float(np.linalg.norm(points[idx] - target, axis=1).mean() * 1e3)


def _fmt(value, width, digits):
    return f"{'':>{width}s}" if np.isnan(value) else f"{value:{width}.{digits}f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=300)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--no-reference", action="store_true", help="skip the torch-autograd anchor")
    args = ap.parse_args(argv)
    config = EDConfig(iterations=args.iterations)
    reference = not args.no_reference
    # warm-up: first-call costs (imports, numba compile or cache load, thread pools) are not the
    # registration's
    P, Q, _ = _generated_pair("tomato", 0)
    t0 = time.perf_counter()
    register_embedded_deformation(P, Q, EDConfig(iterations=2))
    warm = time.perf_counter() - t0
    if reference:
        register_embedded_deformation(P, Q, EDConfig(iterations=2), optimise_autograd)

    cases = [("real tomato 03-05 -> 03-06", _real_pair)]
    for species in ("tomato", "maize"):
        for seed in args.seeds:
            cases.append((f"generated {species} seed {seed}", lambda s=species, k=seed: _generated_pair(s, k)))
    print(f"embedded deformation, {args.iterations} iterations, paper settings, torch threads: {config.threads}; "
          f"warm-up call (numba compile / cache load + 2 iterations): {warm:.2f} s")
    print("new = analytic gradient (numba); ref = torch autograd (the previous implementation), same process")
    head = (f"{'pair':27s} {'P':>6s} {'Q':>5s} {'nodes':>5s} | {'sec':>5s} {'ref sec':>7s} {'speed-up':>8s} | "
            f"{'CD before':>9s} {'CD after':>8s} {'ref':>6s} {'ratio':>6s} | "
            f"{'corr before':>11s} {'after':>6s} {'ref':>6s}")
    print(head)
    print("-" * len(head))
    worst, worst_ratio = 0.0, 0.0
    for name, make in cases:
        P, Q, gt = make()
        r = register_embedded_deformation(P, Q, config)
        worst = max(worst, r.seconds)
        ref_sec = ref_cd = ref_corr = float("nan")
        if reference:
            ref = register_embedded_deformation(P, Q, config, optimise_autograd)
            ref_sec, ref_cd, ref_corr = ref.seconds, ref.chamfer_after * 1e3, _correspondence_mm(ref.warped, gt)
            worst_ratio = max(worst_ratio, r.chamfer_after * 1e3 / ref_cd)
        print(f"{name:27s} {len(P):6d} {len(Q):5d} {r.n_nodes:5d} | {r.seconds:5.2f} {_fmt(ref_sec, 7, 2)} "
              f"{_fmt(ref_sec / r.seconds, 7, 1)}x | {r.chamfer_before * 1e3:9.3f} {r.chamfer_after * 1e3:8.3f} "
              f"{_fmt(ref_cd, 6, 3)} {_fmt(r.chamfer_after * 1e3 / ref_cd, 6, 3)} | "
              f"{_fmt(_correspondence_mm(P, gt), 11, 2)} {_fmt(_correspondence_mm(r.warped, gt), 6, 2)} "
              f"{_fmt(ref_corr, 6, 2)}")
    print("(seconds: graph + optimisation + final warp; Chamfer = symmetric mean distance to Q, mm; "
          "corr = mean distance of ground-truth correspondences, mm)")
    print(f"slowest registration {worst:.2f} s (target <= {TARGET_SECONDS:g} s): "
          f"{'OK' if worst <= TARGET_SECONDS else 'TOO SLOW'}")
    if reference:
        print(f"worst Chamfer-after ratio to the reference {worst_ratio:.4f} (target <= {CHAMFER_TOLERANCE}): "
              f"{'OK' if worst_ratio <= CHAMFER_TOLERANCE else 'WORSE'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
