"""The notebooks' conclusions (issue 51): one function per notebook, each a list of sentences written
from the tables the notebook shows, never a fixed text: a comparison takes its word from the data
(:func:`tpvp.experiments.claims.compare`), a count or a range is read off the table. The notebook's
last cell passes them to ``tpvp.viz.notebook.show_conclusion``."""

from __future__ import annotations

import re

import pandas as pd

from tpvp.experiments import claims
from tpvp.setcover.miss_model import plan_summary, targets_missed


def _in_order(values) -> list:
    """The distinct ``values`` in the order they come."""
    return list(dict.fromkeys(values))


def _range(values, spec: str = ".2f") -> str:
    """``values``' lowest and highest, "1.00-2.00"."""
    return f"{values.min():{spec}}-{values.max():{spec}}"


def _span(values, digits: int = 2) -> str:
    """As :func:`_range`, a single value where both round alike."""
    if round(values.min(), digits) == round(values.max(), digits):
        return f"{values.min():.{digits}f}"
    return _range(values, f".{digits}f")


def _percent(first: str, a: float, second: str, b: float, quantity: str, words=("more", "less"), **kw) -> str:
    """:func:`claims.compare` between two values in %: the gap in points."""
    return claims.compare(first, a, second, b, quantity, unit=" %", words=words, gap_unit=" points", **kw)


def _faster(ratio) -> str:
    """The word for the paper's time over ours (``ratio``, one or many)."""
    return "faster" if ratio.min() > 1 else "slower" if ratio.max() < 1 else "faster or slower"


def getting_started_findings(achieved, frontier: pd.DataFrame) -> list[str]:
    """Notebook 01: the plan's summary (``result.summary()``, "What the plan achieved") and the
    frontier (the plan and the exact optimum per coverage target)."""
    registered = ("brought the previous session closer to" if achieved["chamfer_after_mm"] < achieved["chamfer_before_mm"]
                  else "did not bring the previous session closer to")
    full_plan = frontier.loc[frontier["target"].idxmax()]
    lowest = frontier.loc[frontier["target"].idxmin()]
    as_much = frontier[frontier["optimum_coverage"] >= achieved["coverage"]].sort_values("optimum_views").iloc[0]
    n_plan, n_optimum = int(achieved["views"]), int(as_much["optimum_views"])
    views_against_optimum = ("as many views as" if n_plan == n_optimum else
                             f"{abs(n_plan - n_optimum)} {'more' if n_plan > n_optimum else 'fewer'} views than")
    met, short = frontier[frontier["coverage"] >= frontier["target"]], frontier[frontier["coverage"] < frontier["target"]]
    kept = (f"its true coverage reached the target for {len(met)} of the {len(frontier)} targets"
            + (f" (the highest: {100 * met['target'].max():g} %)" if len(met) else ""))
    kept += (f" and fell short of the others by up to {100 * (short['target'] - short['coverage']).max():.2f} points"
             if len(short) else "")
    extra = int(full_plan["optimum_views"] - lowest["optimum_views"])
    return [
        f"On the bundled tomato pair the plan executes {n_plan} views ({achieved['warm_up_views']} before planning: the "
        f"initial view and the warm-up NBV; {achieved['planned_views']} planned at once), sees "
        f"{100 * achieved['coverage']:.1f} % of the oracle set and travels {achieved['path_length_m']:.2f} m. The "
        f"registration {registered} the coarse scan (Chamfer distance {achieved['chamfer_before_mm']:.1f} mm before, "
        f"{achieved['chamfer_after_mm']:.1f} mm after).",
        f"The plan used {views_against_optimum} the exact optimum needs, with perfect knowledge of today's plant, to "
        f"see as much ({n_optimum} views for {100 * as_much['optimum_coverage']:.1f} %).",
        f"The frontier, views per coverage level: asking for {100 * lowest['target']:g} % the plan takes "
        f"{int(lowest['views'])} views, asking for {100 * full_plan['target']:g} % it takes {int(full_plan['views'])}; "
        f"the exact optimum needs {int(lowest['optimum_views'])} and {int(full_plan['optimum_views'])}"
        + (f", so the last {100 * (full_plan['target'] - lowest['target']):g} points cost it {extra} views"
           if extra > 0 else "")
        + f". The plan counts a predicted surface: {kept}.",
        "For monitoring, read this frontier before choosing `selection.coverage_target`: `tpvp plan ... --frontier` "
        "prints it for your own plant.",
    ]


def table1_findings(table1: pd.DataFrame, optimum_ratio: pd.DataFrame, raw: pd.DataFrame) -> list[str]:
    """Notebook 02: Table I (``table1``), Ours' views over the exact optimum's (``optimum_ratio``)
    and the robot-frame and sensor-noise runs (``raw``, the ``frame`` x ``noise`` world's rows)."""
    means = table1.set_index(["source", "view_space", "method"])
    partial = table1.loc[table1["method"] == "optimum", "target"].min()  # the optimum's target below 100 %
    ratio = optimum_ratio.set_index(["source", "view_space", "method"])
    spaces = _in_order(table1["view_space"])

    def without_prior(space):
        ours, bare = means.loc[("generated", space, "ours")], means.loc[("generated", space, "one-shot-no-prior")]
        return (f"on the {space} " + _percent("a plan without the prior sees", bare["coverage_mean"], "Ours",
                                              ours["coverage_mean"], "of the oracle set")
                + ", with " + claims.compare("", bare["views_mean"], "Ours'", ours["views_mean"], "views",
                                             digits=1).strip())

    gain = {(source, space): means.loc[(source, space, "ours"), "coverage_mean"]
            - means.loc[(source, space, "one-shot-no-prior"), "coverage_mean"]
            for source in ("generated", "bundled") for space in spaces}
    sensors = ["arm-rgbd", "phone-lidar"]
    noisy = raw[raw["frame"] == "current"].set_index(["noise", "view_space"])
    known = raw[(raw["frame"] == "previous") & (raw["noise"] == "ideal")].set_index("view_space")
    coverage = noisy.loc[sensors, "coverage vs current/ideal (points)"]
    return [
        "Ours against GMC at the same coverage, from Table I's means. " + claims.ours_against_gmc(table1),
        "What the previous session buys (generated pairs): " + "; ".join(without_prior(space) for space in spaces)
        + f". On either pair set and view space the prior adds at most {max(gain.values()):.2f} points of coverage "
        + "(bundled real pair: "
        + ", ".join(f"{gain[('bundled', space)]:+.2f} points on the {space}" for space in spaces) + ").",
        "Ours' views over those of the exact optimum that sees as much with perfect knowledge of today's plant: "
        + " and ".join(f"{ratio.loc[('generated', space, 'ours'), 'views_ratio_mean']:.2f}x on the {space}"
                       for space in spaces)
        + " (generated pairs; bundled: "
        + ", ".join(f"{ratio.loc[('bundled', space, 'ours'), 'views_ratio_mean']:.2f}x" for space in spaces)
        + f"); over the optimum for {100 * partial:g} %, where Ours reached it: "
        + " and ".join(f"{ratio.loc[('generated', space, 'ours'), 'views_ratio_98_mean']:.2f}x" for space in spaces)
        + ". That is the price of planning on a prediction.",
        "On a robot (Ours only, not a paper table): planning in the frame it can know multiplies the views by "
        + " and ".join(f"{known.loc[space, 'views vs current/ideal']:.2f} on the {space}" for space in spaces)
        + "; noisy captures multiply them by "
        + ", ".join(" and ".join(f"{noisy.loc[(noise, space), 'views vs current/ideal']:.2f} on the {space}"
                                 for space in spaces) + f" ({noise})" for noise in sensors)
        + f", and change coverage by {coverage.min():+.2f} to {coverage.max():+.2f} points: budget the views for the "
          "sensor, not for the simulation.",
    ]


def _how_often(share: float, alpha: float) -> str:
    """How often the true coverage falls below the bound, against the bound's promise ``alpha``, with
    the evaluation's tolerance (:func:`tpvp.setcover.miss_model.targets_missed`)."""
    return f"{100 * share:.1f} %" + (" (more often than promised)" if share > alpha + 0.02 else
                                     " (less often than promised: a cautious bound)" if share < alpha - 0.02 else "")


def plant_complexity_findings(ours: dict, paper_ii: dict, theirs: dict, generated: pd.DataFrame,
                              occlusion: pd.DataFrame, ideal_raw: pd.DataFrame, species_tables: dict, *,
                              alpha: float, rule: str, target: float, organ_targets: str) -> list[str]:
    """Notebook 03: Table II's ordering (``ours`` and ``paper_ii``: the differences; ``theirs``: the
    paper's views per (species, view space); ``generated``: our Table II rows), the occlusion counts
    of the pair taken apart (``occlusion``), the miss model's evaluation with the ideal sensor
    (``ideal_raw``; ``alpha``, the default ``rule``) and the Helios species (``species_tables``,
    planned for ``target`` and for ``organ_targets``)."""
    ordering = claims.ordering(ours, paper_ii, {"species": "views, tomato minus maize (hemisphere)",
                                                "view space": "views, tomato on the sphere minus the hemisphere"})
    ours_ii = generated.set_index(["species", "view_space"])
    occlusion = occlusion.set_index(["species", "view_space"])
    few = occlusion.filter(like="at_most").squeeze(axis=1)  # the share of the oracle set seen by at most two views
    tomato_h, tomato_s, maize_h = (occlusion.loc[key] for key in [("tomato", "hemisphere"), ("tomato", "sphere"),
                                                                    ("maize", "hemisphere")])
    ideal = plan_summary(ideal_raw, by=("rule", "view_space"))
    constant = ideal[ideal["rule"] == rule].reset_index(drop=True)
    missed = targets_missed(constant, alpha)
    asked, sure = 100 * target, 100 * (1 - alpha)
    prediction, organs = species_tables["prediction"], species_tables["organ_targets"]
    return [
        f"Table II's ordering: {ordering} The size differs: "
        + claims.compare("the hemisphere's tomato-minus-maize gap is", ours["species"], "the paper's",
                         paper_ii["species"], "views", words=("larger", "smaller"))
        + ": on the hemisphere " + "; ".join(
            claims.compare(f"our {name} takes", ours_ii.loc[(name, "hemisphere"), "views_mean"], "the paper's",
                           theirs[(name, "hemisphere")], "views") for name in ("maize", "tomato"))
        + " (generated plants, see the list under Table II).",
        "Why, on the pair taken apart above: "
        + _percent("the tomato has", few[("tomato", "hemisphere")], "the maize", few[("maize", "hemisphere")],
                   "of its oracle voxels seen by at most two hemisphere views", words=("more", "fewer"), digits=1)
        + ", and " + claims.compare("", tomato_h["forced_views"], "the maize's", maize_h["forced_views"],
                                    "forced views (the only view of some voxel)", digits=0).strip()
        + f"; with views from below (sphere) the tomato is left with {few[('tomato', 'sphere')]:.1f} % of such "
          f"voxels and {int(tomato_s['forced_views'])} forced views, and Ours executes {int(tomato_s['ours_views'])} "
          f"views instead of {int(tomato_h['ours_views'])}.",
        f"How sure a plan is (the miss model, the default {rule} rule, plans asked {asked:g} %, ideal sensor): mean "
        f"true coverage "
        + " and ".join(f"{100 * row.coverage_mean:.2f} % on the {row.view_space}" for row in constant.itertuples())
        + f"; below the {sure:g} % lower bound: "
        + " and ".join(f"{_how_often(row.below_bound, alpha)} on the {row.view_space}" for row in constant.itertuples())
        + "; targets missed: "
        + "; ".join(f"{row.view_space}: " + (", ".join(m) if m else "none")
                    for row, m in zip(constant.itertuples(), missed))
        + ". On the Helios evaluation species the true coverage falls below the bound in "
        + " and ".join(f"{_how_often(row.below_bound, alpha)} of the cases on the {row.view_space}"
                       for row in prediction.itertuples())
        + (": on a species it was not fitted on, read the bound as a guide, not a guarantee."
           if (prediction["below_bound"] > alpha + 0.02).any() else "."),
        f"Across the Helios evaluation species (planned for {asked:g} %): mean true coverage "
        + " and ".join(f"{100 * row.coverage_mean:.2f} % (lowest {100 * row.coverage_min:.2f} %) on the "
                       f"{row.view_space}" for row in species_tables["overall"].itertuples())
        + f". Asking for the fruits in full and the rest in part ({organ_targets}) saves "
          f"{_range(100 * organs['views_saved'], '.0f')} % of the views of a full cover, "
          f"with the true fruit coverage of the worst case at {100 * organs['fruit_min'].min():.1f} %.",
    ]


def ablation_findings(table3: pd.DataFrame, table4: pd.DataFrame, paper: pd.DataFrame,
                      pooled: pd.DataFrame) -> list[str]:
    """Notebook 04: Tables III and IV beside the paper's (``paper``: its ``table`` III, IV and
    ``text`` rows) and the pooled table (``tpvp.experiments.ablation.pooled_table``)."""
    ours3 = table3.set_index(["source", "species", "method"])
    theirs3 = paper[paper["table"] == "III"].set_index(["species", "method"])
    theirs4 = paper[paper["table"] == "IV"].set_index("method")["chamfer_mean"]
    ours4 = table4.set_index(["source", "method"])
    pooled = pooled.set_index(["source", "method"])
    paper_text = paper[paper["table"] == "text"].set_index("method")["coverage_mean"]

    def inflation(species):
        value = ["views_mean", "coverage_mean"]
        ours = (ours3.loc[("generated", species, "ours"), value]
                - ours3.loc[("generated", species, "ours-no-inflation"), value])
        theirs = theirs3.loc[(species, "ours"), value] - theirs3.loc[(species, "ours-no-inflation"), value]
        return (claims.compare(f"on {species} it adds", ours["coverage_mean"], "the paper's", theirs["coverage_mean"],
                               "of coverage", unit=" points", words=("more", "less"))
                + f" for {ours['views_mean']:+.2f} views (the paper: {theirs['views_mean']:+.2f})")

    maize_bare = ours3.loc[("generated", "maize", "ours-no-inflation"), "coverage_mean"]
    paper_maize_bare = theirs3.loc[("maize", "ours-no-inflation"), "coverage_mean"]
    truth, coarse = ours4["chamfer_truth_mm_mean"], ours4["chamfer_after_mm_mean"]
    moved_truth = truth[("generated", "ours")] - truth[("generated", "initial-view-only")]
    moved_coarse = coarse[("generated", "ours")] - coarse[("generated", "initial-view-only")]
    full, bare = pooled.loc[("generated", "ours")], pooled.loc[("generated", "initial-view-only-no-inflation")]
    return [
        "What inflation buys (Table III, generated pairs): " + "; ".join(inflation(s) for s in ("maize", "tomato"))
        + ". " + _percent("Without inflation our maize plans see", maize_bare, "the paper's", paper_maize_bare,
                          "of the oracle set")
        + (": less is left for inflation to add." if maize_bare > paper_maize_bare else "."),
        "Table IV: " + claims.compare("after the warm-up NBV the transferred model sits", truth[("generated", "ours")],
                                      "on the initial view alone", truth[("generated", "initial-view-only")],
                                      "from today's plant (Chamfer)", unit=" mm", words=("farther", "closer"))
        + f" (the paper: {theirs4['ours']:.2f} mm and {theirs4['initial-view-only']:.2f} mm). "
        + claims.compare("Our transfer is", truth[("generated", "ours")], "the paper's", theirs4["ours"],
                         "from today's plant", unit=" mm", words=("farther", "closer"))
        + f"; the bundled real pair gives {truth[('bundled', 'ours')]:.2f} mm"
        + (", so generated plants alone do not explain the gap." if truth[("bundled", "ours")] < theirs4["ours"]
           else "."),
        f"With the warm-up NBV the registration's own residual, its Chamfer distance to the coarse scan, changes by "
        f"{moved_coarse:+.2f} mm, the distance to today's plant by {moved_truth:+.2f} mm"
        + (": the residual does not show how good the transfer is, and a robot cannot measure the distance to "
           "today's plant, so keep the warm-up NBV." if abs(moved_coarse) < abs(moved_truth) / 4 and moved_truth < 0
           else "."),
        "Together the warm-up NBV and inflation (Ours against the initial view only without inflation, generated "
        f"pairs, pooled) cost {full['views_mean'] - bare['views_mean']:+.2f} views and "
        f"{full['path_length_m_mean'] - bare['path_length_m_mean']:+.2f} m of path for "
        f"{full['coverage_mean'] - bare['coverage_mean']:+.2f} points of coverage; "
        + _percent("without both, our plans see", bare["coverage_mean"], "the paper's text",
                   paper_text["initial-view-only-no-inflation"], "of the oracle set")
        + ".",
    ]


def greenhouse_rows_findings(table6: pd.DataFrame, references: list, ours: pd.DataFrame, nbv: pd.DataFrame,
                             random: pd.DataFrame, coarse_voxel, fine_voxel) -> list[str]:
    """Notebook 05: Table VI's rows (``table6``, every reference in ``references``); with the first
    reference: Ours per covering voxel (``ours``; ``coarse_voxel`` / ``fine_voxel`` its coarsest /
    finest), Block-wise NBV per budget (``nbv``) and PriorTransfer random (``random``)."""
    cheapest = nbv.sort_values("budget").iloc[0]  # Block-wise NBV at its smallest budget
    voxel = f"{coarse_voxel.cover_resolution_cm:g} cm"
    ahead = cheapest.coverage_mean >= coarse_voxel.coverage_mean and cheapest.views_mean <= coarse_voxel.views_mean

    def nbv_ahead(reference):
        rows = table6[table6["reference"] == reference]
        smallest = rows[rows["method"] == "blockwise-nbv"].sort_values("budget").iloc[0]
        coarse = rows[(rows["method"] == "ours") & (rows["cover_resolution_cm"] == coarse_voxel.cover_resolution_cm)]
        return smallest.coverage_mean >= coarse.iloc[0].coverage_mean

    nbv_ahead_in = [r for r in references if nbv_ahead(r)]
    ours_all = table6[table6["method"] == "ours"]
    views_spread = (ours_all.groupby("cover_resolution_cm")["views_mean"]
                    .agg(lambda v: 100 * (v.max() / v.min() - 1)).max())
    coverage_spread = ours_all.groupby("cover_resolution_cm")["coverage_mean"].agg(lambda v: v.max() - v.min()).max()
    coarse_all = ours_all[ours_all["cover_resolution_cm"] == coarse_voxel.cover_resolution_cm]["views_mean"]
    sweep = table6[table6["method"] == "coarse"].set_index("reference")
    paper_sweep = sweep["paper_coverage"].iloc[0]
    sweep_said = ", ".join(f"{r} {sweep.loc[r, 'coverage_mean']:.1f} %" for r in references)
    swept = sweep.loc[references, "coverage_mean"]
    below, above = swept[swept <= paper_sweep], swept[swept > paper_sweep]
    where = (f"between `{below.idxmax()}` and `{above.idxmin()}`" if len(below) and len(above) else
             "above every reference's" if len(below) else "below every reference's")
    # Ours against random selection over the same candidates at the closest number of views
    pairs = [(o, r) for _, o in ours.iterrows() for _, r in random.iterrows()]
    at_par = min(pairs, key=lambda p: abs(p[0].views_mean - p[1].views_mean))
    extra_views = fine_voxel.views_mean - coarse_voxel.views_mean
    extra_path = fine_voxel.path_length_m_mean - coarse_voxel.path_length_m_mean
    rising = ours.sort_values("cover_resolution_cm", ascending=False)["coverage_mean"].is_monotonic_increasing
    points = ("points more", "points less")
    return [
        f"With the {references[0]} reference, Block-wise NBV at its {cheapest.budget:.0f}-view budget against Ours at "
        f"{voxel}: " + claims.compare("Block-wise NBV", cheapest.coverage_mean, "Ours", coarse_voxel.coverage_mean,
                                      "% of the oracle", words=points)
        + "; " + claims.compare("it takes", cheapest.views_mean, "Ours", coarse_voxel.views_mean, "views", digits=1)
        + "; " + claims.compare("it travels", cheapest.path_length_m_mean, "Ours'", coarse_voxel.path_length_m_mean,
                                "of path", unit=" m", digits=1, words=("longer", "shorter"))
        + ". " + (f"So here Block-wise NBV beats Ours at {voxel} on both coverage and views" if ahead else
                  f"So here Block-wise NBV does not beat Ours at {voxel} on both coverage and views")
        + (", and Ours' edge is its path alone"
           if ahead and coarse_voxel.path_length_m_mean < cheapest.path_length_m_mean else "")
        + f" (its smallest budget sees at least as much as Ours at {voxel} with {len(nbv_ahead_in)} of the "
          f"{len(references)} references).",
        claims.compare(f"Ours at {voxel} selects", coarse_voxel.views_mean, "the paper", coarse_voxel.paper_views,
                       "views", digits=1)
        + f", {coarse_voxel.views_mean / coarse_voxel.paper_views:.1f}x as many ({_range(coarse_all, '.1f')} "
          f"across the references); at {fine_voxel.cover_resolution_cm:g} cm "
        + claims.compare("", fine_voxel.views_mean, "the paper", fine_voxel.paper_views, "views", digits=1).strip()
        + ". The lines under Table VI explain it: the paper's rows are real handheld scans, ours generated rows; "
          "[results.md](../docs/results.md#greenhouse-rows-tables-v-vii) measured how: in these rows candidates see "
          "voxels deep in the canopy through gaps, and each such voxel forces a view of its own.",
        f"Which reference stands for the paper's setting: `handheld` emulates the paper's handheld phone scan from the "
        f"aisle (`candidates` keeps what the room's own candidate positions see, `complete` every point of the "
        f"generated row; [greenhouse.md](../docs/greenhouse.md#generated-rows-as-a-scan-sees-them)). The passive "
        f"sweep sees {sweep_said} of the oracle; the paper's {paper_sweep:.1f} % lies {where}. Between references "
        f"Ours' coverage moves by up to {coverage_spread:.1f} points, its views by at most {views_spread:.1f} %.",
        f"For a row robot ({references[0]} reference): "
        + claims.compare(f"Ours at {at_par[0].cover_resolution_cm:g} cm sees", at_par[0].coverage_mean,
                         "random selection over the same candidates", at_par[1].coverage_mean, "% of the oracle",
                         words=points)
        + f" at a similar number of views ({at_par[0].views_mean:.1f} and {at_par[1].views_mean:.0f})"
        + f"; its coverage {'rises' if rising else 'does not rise steadily'} as the covering voxel shrinks, from "
          f"{coarse_voxel.coverage_mean:.2f} % at {voxel} to {fine_voxel.coverage_mean:.2f} % at "
          f"{fine_voxel.cover_resolution_cm:g} cm, at the cost of {abs(extra_views):.0f} "
          f"{'more' if extra_views > 0 else 'fewer'} views and {abs(extra_path):.1f} m "
          f"{'more' if extra_path > 0 else 'less'} path: choose the covering voxel for the detail the traits need.",
    ]


def _shape(chamfer, precision) -> dict:
    """The signs of Table VII's shape (columns of its noise-free row ``-`` and its largest level
    ``OFF`` / ``ON``): what the largest noise does without ICP, and what ICP does to it."""
    return {"chamfer": chamfer["OFF"] - chamfer["-"], "precision": precision["OFF"] - precision["-"],
            "icp": chamfer["ON"] - chamfer["OFF"]}


def pose_noise_findings(table7: pd.DataFrame, paper7: pd.DataFrame, free, largest: pd.DataFrame,
                        tau_m: float) -> list[str]:
    """Notebook 06: Table VII (``table7``) beside the paper's (``paper7``,
    ``tpvp.experiments.rows.paper_pose_noise()``); ``free`` the noise-free row, ``largest`` the
    largest noise level per ICP (``OFF`` / ``ON``); ``tau_m`` the precision and recall distance."""
    both = table7.merge(paper7, on=["sigma_t_m", "sigma_r_deg", "icp"], suffixes=("", "_paper"))
    both = both.sort_values("sigma_t_m").set_index("icp", drop=False)
    off, on = both.loc[["OFF"]], both.loc[["ON"]]
    tau = f"{100 * tau_m:g} cm"
    chamfers = ", ".join(f"{v:.2f}" for v in off.chamfer_mm_mean)
    precisions = ", ".join(f"{v:.1f}" for v in off.precision_10mm_mean)
    levels = ", ".join(f"{t:g} m / {r:g}°" for t, r in zip(off.sigma_t_m, off.sigma_r_deg))
    grows = off.chamfer_mm_mean.is_monotonic_increasing and off.chamfer_mm_mean.iloc[0] > free.chamfer_mm_mean
    falls = (off.precision_10mm_mean.is_monotonic_decreasing
             and off.precision_10mm_mean.iloc[0] < free.precision_10mm_mean)
    drift = (on.chamfer_mm_mean - free.chamfer_mm_mean).abs().max()
    top = both[(both.sigma_t_m == both.sigma_t_m.max()) | (both.icp == "-")]  # noise-free and the largest level
    recall_gap = both.recall_10mm_mean - both.recall_1cm_mean
    held, unheld = recall_gap[both.icp != "OFF"], recall_gap[both.icp == "OFF"]
    worst_off, worst_on = largest.loc["OFF"], largest.loc["ON"]
    return [
        f"Without ICP, Chamfer {'grows' if grows else 'does not grow steadily'} with the noise (noise-free "
        f"{free.chamfer_mm_mean:.2f} mm; {chamfers} mm at {levels}) and "
        f"precision at {tau} {'falls' if falls else 'does not fall steadily'} ({free.precision_10mm_mean:.1f} %; "
        f"{precisions} %). With ICP, Chamfer stays within {drift:.2f} mm "
        f"of the noise-free fusion and precision at {tau} at or above {on.precision_10mm_mean.min():.1f} % at every "
        "level.",
        "Against the paper's shape, from the largest level: "
        + claims.ordering(_shape(top.chamfer_mm_mean, top.precision_10mm_mean),
                          _shape(top.chamfer_mm_mean_paper, top.precision_1cm_mean),
                          {"chamfer": "noise without ICP on Chamfer (mm)",
                           "precision": f"noise without ICP on precision at {tau} (points)",
                           "icp": "ICP on Chamfer (mm)"})
        + " " + claims.compare("Without ICP our precision there is", worst_off.precision_10mm_mean, "the paper's",
                               top.precision_1cm_mean["OFF"], "%", digits=1, words=("points more", "points less"))
        + ": our degradation is " + ("milder." if worst_off.precision_10mm_mean > top.precision_1cm_mean["OFF"]
                                     else "not milder."),
        f"Recall at {tau} is {_range(both.recall_10mm_mean, '.1f')} % here, the paper's "
        f"{_range(both.recall_1cm_mean, '.1f')} %: {held.min():+.1f} to {held.max():+.1f} points "
        f"against the paper noise-free and with ICP, {unheld.min():+.1f} to {unheld.max():+.1f} without ICP. The lines "
        "under Table VII put the gaps down to our noise protocol (neither the paper nor the authors' code states one); "
        "our fused views are voxel centres of a simulator on a ground truth that is itself a scan from the aisle, "
        "where the paper fuses renderings of a NeRF reconstruction "
        "([results.md](../docs/results.md#greenhouse-rows-tables-v-vii)).",
        f"On a robot whose arm or hand-eye calibration errs by up to {worst_off.sigma_t_m:g} m and "
        f"{worst_off.sigma_r_deg:g}°, refine each view by ICP against the passive map before measuring traits: there "
        f"it takes Chamfer from {worst_off.chamfer_mm_mean:.2f} mm to {worst_on.chamfer_mm_mean:.2f} mm and precision "
        f"at {tau} from {worst_off.precision_10mm_mean:.1f} % to {worst_on.precision_10mm_mean:.1f} % (noise-free: "
        f"{free.chamfer_mm_mean:.2f} mm, {free.precision_10mm_mean:.1f} %).",
    ]


#: The runner's planning stages, in their order (its ``seconds_<stage>`` columns).
_STAGES = ["registration", "inflation", "targets", "visibility", "selection", "path"]


def _cores(text) -> str | None:
    """The core count a machine's description names ("... 16 cores ..."), None where it names none."""
    found = re.search(r"(\d+) cores", str(text))
    return found[1] if found else None


def _against(paper: pd.DataFrame, stage: str, ours) -> str:
    """Ours' seconds for a stage (every covering voxel) against the paper's range, in words."""
    row = paper[paper["stage"] == stage].iloc[0]
    low, high = row["paper_seconds_low"], row["paper_seconds_high"]
    where = ("below" if ours.max() < low else "above" if ours.min() > high else
             "within" if ours.min() >= low and ours.max() <= high else "overlapping")
    return f"ours {_span(ours)} s, {where} the paper's {low:g}" + (f"-{high:g}" if high != low else "") + " s"


def planning_time_findings(timing: pd.DataFrame, nbv: pd.DataFrame, paper: pd.DataFrame, stages: pd.DataFrame,
                           source: str) -> list[str]:
    """Notebook 07: the runner's stages in the paper's protocol per covering voxel (``timing``),
    Block-wise NBV per budget (``nbv``), the paper's times (``paper``, Sec. V, its ``note`` naming
    its machine), the notebook's live run (``stages``) and our machine (``source``)."""
    per_voxel = timing.set_index("cover_resolution_cm")[[f"seconds_{n}" for n in _STAGES]]
    longest = per_voxel.idxmax(axis=1).str.removeprefix("seconds_")
    live_longest = {}  # the live run: the longest stage -> the covering voxels where it is the longest
    for value, (stage, _) in reversed(claims.longest_stage(stages).items()):
        live_longest.setdefault(stage, []).append(f"{value:g}")
    paper_cores, our_cores = _cores(" ".join(paper["note"].dropna())), _cores(source)
    share = 100 * timing["seconds_visibility"] / timing["seconds_planning"]
    ratio = timing["paper_visibility_s"] / timing["seconds_visibility"]
    voxels = " / ".join(f"{v:g}" for v in timing["cover_resolution_cm"])
    nbv_ratio = nbv["paper_seconds_per_iteration"] / nbv["seconds_per_iteration"]
    first_budget = nbv.sort_values("budget").iloc[0]
    coarsest = timing.sort_values("cover_resolution_cm").iloc[-1]
    both_grow = all(timing.sort_values("cover_resolution_cm")[c].is_monotonic_decreasing
                    for c in ("seconds_visibility", "paper_visibility_s"))
    visibility = (
        f"The visibility runs {_range(ratio, ',.0f')}x {_faster(ratio)} than the paper's"
        + (f", on {our_cores} cores against the paper's {paper_cores}" if our_cores and paper_cores else "")
        + ": ours ray casts the planning voxels with numba, the paper an OctoMap. Both grow as the covering voxel "
          f"shrinks (ours {_span(timing['seconds_visibility'])} s, the paper's "
          f"{_range(timing['paper_visibility_s'], ',.0f')} s at {voxels} cm)."
        if both_grow else
        f"The visibility runs {_range(ratio, ',.0f')}x {_faster(ratio)} than the paper's: ours ray casts the "
        "planning voxels with numba, the paper an OctoMap.")
    return [
        "Where the time goes (the runner's rows, the paper's protocol): "
        + (f"at every covering voxel ({voxels} cm) the longest stage is {longest.iloc[0]} "
           f"({_span(per_voxel[f'seconds_{longest.iloc[0]}'])} s)" if longest.nunique() == 1 else
           "; ".join(f"at {v:g} cm the longest stage is {s}" for v, s in longest.items()))
        + "; in this notebook's live run the longest is "
        + ", ".join(f"{stage} at {' / '.join(at)} cm" for stage, at in live_longest.items())
        + f". The visibility, the paper's dominant stage, is {_range(share, '.0f')} % of our planning time: "
        + ("it dominates here too." if set(longest) == {"visibility"}
           else "the paper's ranking of the stages is not reproduced."),
        visibility,
        f"Ours plans a session in {_span(timing['seconds_planning'])} s. "
        + claims.compare(f"Block-wise NBV plans its {first_budget['budget']:.0f} views in",
                         first_budget["seconds_planning"], f"Ours at {coarsest['cover_resolution_cm']:g} cm",
                         coarsest["seconds_planning"], "of planning", unit=" s", words=("more", "less"))
        + f", its {nbv['budget'].max()} views in {nbv['seconds_planning'].max():.1f} s; each of its iterations runs "
          f"{_range(nbv_ratio, '.0f')}x {_faster(nbv_ratio)} than the paper's.",
        f"For a row scanned every few days planning is no bottleneck here: at most "
        f"{timing['seconds_planning'].max():.1f} s per session, so choose the covering voxel for the detail the traits "
        "need, not for the time.",
    ]


def planning_time_against_paper(timing: pd.DataFrame, nbv: pd.DataFrame, paper: pd.DataFrame) -> list[str]:
    """Notebook 07's lines against the paper: Sec. V's times per stage against the runner's rows
    (``timing``, ``nbv``, ``paper`` as for :func:`planning_time_findings`)."""
    ratio = timing["paper_visibility_s"] / timing["seconds_visibility"]
    return [
        "Sec. V's times per stage (the paper gives no table) against the runner's rows above, at every covering voxel:",
        f"Visibility: ours {_span(timing['seconds_visibility'])} s, the paper's "
        f"{_range(timing['paper_visibility_s'], ',.0f')} s ({_range(ratio, ',.0f')}x {_faster(ratio)}).",
        "Registration: " + _against(paper, "registration", timing["seconds_registration"]) + ".",
        "Set cover: " + _against(paper, "selection", timing["seconds_selection"]) + ".",
        "Path: " + _against(paper, "path", timing["seconds_path"]) + ".",
        "Block-wise NBV, one iteration: " + _against(paper, "nbv_iteration", nbv["seconds_per_iteration"]) + ".",
    ]


#: The learned baselines' names as the paper writes them.
_NETWORKS = {"ma-scvp": "MA-SCVP", "pc-nbv": "PC-NBV"}


def learned_baselines_findings(networks, held_out, table1: pd.DataFrame, paper: pd.DataFrame,
                               comparison: pd.DataFrame, timing) -> list[str]:
    """Notebook 08: the shipped networks (``networks``), their held-out metrics (``held_out``, the
    shipped run's test split first), Table I (``table1``) and the paper's (``paper``), PC-NBV as the
    warm-up NBV (``comparison``) and the inference time (``timing``)."""
    nets = pd.DataFrame(networks).set_index("network")
    shipped_test = pd.DataFrame(held_out).groupby("network").first()
    table1 = table1.set_index(["source", "view_space", "method"])
    paper_i = paper[paper["table"] == "I"].set_index(["view_space", "method"])
    spaces = _in_order(table1.index.get_level_values("view_space"))
    speed = pd.DataFrame(timing).set_index("network")
    warm = comparison["views_mean"].unstack("method")
    warm_gap = (warm["ours-pc-nbv"] - warm["ours"]).abs().max()
    pairs = [(s, v) for s, v, m in table1.index if m == "ours"]
    ours_fewer = sum(table1.loc[(s, v, "ours"), "views_mean"] < table1.loc[(s, v, "ma-scvp"), "views_mean"]
                     for s, v in pairs)
    slowest = speed["ms_per_call_max"].max()

    def smaller(kind):
        ratio = nets.loc[kind, "published_parameters"] / nets.loc[kind, "parameters"]
        return (f"{_NETWORKS[kind]} {nets.loc[kind, 'parameters']:,} parameters, {max(ratio, 1 / ratio):.0f}x "
                f"{'fewer' if ratio > 1 else 'more'} than the authors' {nets.loc[kind, 'published_parameters']:,}")

    def on_space(space):
        ours, ma, oracle = (table1.loc[("generated", space, m)] for m in ("ours", "ma-scvp", "ma-scvp-oracle"))
        return (f"on the {space} "
                + claims.compare("MA-SCVP", ma["views_mean"], "Ours", ours["views_mean"], "views", digits=1)
                + f" for {ma['coverage_mean']:.2f} % against {ours['coverage_mean']:.2f} % (with its oracle labels "
                  f"{oracle['views_mean']:.1f} views)")

    def ma_minus_ours(views):
        return {space: views(space, "ma-scvp") - views(space, "ours") for space in spaces}

    test = shipped_test.loc
    return [
        "The networks are retrained here on generated plants: " + "; ".join(smaller(kind) for kind in nets.index)
        + f"; both on {nets['training_plants'].iloc[0]} plants ({nets['training_states'].iloc[0]:,} states), in "
        + " and ".join(f"{nets.loc[kind, 'training_minutes']:.0f} min" for kind in nets.index)
        + ". The lines under Table I put MA-SCVP's gaps to the paper down to this.",
        "Table I, generated pairs: " + "; ".join(on_space(space) for space in spaces)
        + ". MA-SCVP against Ours in views, "
        + claims.ordering(ma_minus_ours(lambda space, m: table1.loc[("generated", space, m), "views_mean"]),
                          ma_minus_ours(lambda space, m: paper_i.loc[(space, m), "views_mean"]),
                          {space: f"on the {space}" for space in spaces}),
        f"On held-out plants (the shipped run's test split) MA-SCVP recalls {test['ma-scvp', 'recall']:.2f} of "
        f"the label set at a precision of {test['ma-scvp', 'precision']:.2f}, predicting "
        f"{test['ma-scvp', 'mean_predicted_size']:.1f} views for {test['ma-scvp', 'mean_label_size']:.1f} "
        f"in the label; PC-NBV's predicted gains follow the true ones with a Spearman correlation of "
        f"{test['pc-nbv', 'spearman']:.2f}, and its chosen view ranks {test['pc-nbv', 'chosen_rank']:.1f} "
        f"by true gain on average (a best view in {100 * test['pc-nbv', 'chosen_best']:.0f} % of the states). As "
        f"Ours' warm-up NBV, PC-NBV changes Ours' mean final views by at most {warm_gap:.1f}.",
        "Inference per call here, median: "
        + ", ".join(f"{_NETWORKS[kind]} {speed.loc[kind, 'ms_per_call_median']:.1f} ms" for kind in speed.index)
        + f" (the slowest call {slowest:.0f} ms, "
        + ("under a second: fast enough to plan on a robot" if slowest < 1e3 else "a second or more at worst")
        + f"); on views, though, Ours needs the fewer in {ours_fewer} of the {len(pairs)} pair and view-space rows of "
          "Table I.",
    ]


def prepared_data_findings(manifest, pairs, cleaned: pd.DataFrame, residuals: pd.DataFrame, accuracy: pd.DataFrame,
                           frames: int, phone_plans: pd.DataFrame, plans) -> list[str]:
    """Notebook 09: what the data tools produced: the single-plant preparation (``manifest``,
    ``pairs``), the cleaned captures (``cleaned``), the alignment residuals (``residuals``), the
    phone scan fused from ``frames`` frames (``accuracy``: the whole plant, then what the capture
    saw) and the plans from it and from the generated plant (``phone_plans``, named by ``plans``)."""
    kept = 100 * cleaned["points"] / cleaned["points_raw"]
    later = residuals[residuals["alignment"] != "reference day"]
    icp, corners = later["ICP inlier RMSE (mm)"], later["true error at box corners (mm)"]
    whole, saw = accuracy.iloc[0], accuracy.iloc[1]
    phone_plan, perfect_plan = (phone_plans.set_index("previous session").loc[name] for name in plans)
    return [
        f"The single-plant preparation wrote {len(manifest)} scans and {len(pairs)} planning pair from the "
        f"bundled samples; `greenhouse clean` kept {_range(kept, '.1f')} % of each raw capture's points "
        f"({_range(cleaned['points'], ',')} of {_range(cleaned['points_raw'], ',')}) after cropping, support and "
        "outlier removal and downsampling.",
        f"The {len(later)} later sessions align to the first day with an ICP fitness of "
        f"{_range(later['ICP fitness'], '.3f')} and a landmark fit of {_range(later['landmark fit RMSE (mm)'], '.1f')} "
        "mm; "
        + claims.compare("the recovered transforms' true error at the plant box's corners is", corners.max(),
                         "ICP's inlier RMSE", icp.min(), "at most", unit=" mm", words=("larger", "smaller"))
        + (": that RMSE reflects the noise and the downsampling, not the alignment error."
           if corners.max() < icp.min() else "."),
        f"`capture fuse` turned the phone's {frames} frames into {int(whole['fused points']):,} points with a "
        f"Chamfer distance of {whole['Chamfer (mm)']:.2f} mm to the generated plant ({saw['Chamfer (mm)']:.2f} mm to "
        f"the {100 * saw['truth points'] / whole['truth points']:.0f} % of it the capture saw).",
        claims.compare("Planned from the phone scan, today's session takes", phone_plan["views"],
                       "from the generated plant", perfect_plan["views"], "views", digits=0, words=("more", "fewer"))
        + "; " + _percent("it sees", 100 * phone_plan["coverage"], "the other plan", 100 * perfect_plan["coverage"],
                          "of today's plant")
        + ", and " + claims.compare("its path is", phone_plan["path_length_m"], "the other's",
                                    perfect_plan["path_length_m"], "long", unit=" m", words=("longer", "shorter"))
        + (": a phone scan can stand in for the previous session, at the price of some coverage."
           if phone_plan["coverage"] < perfect_plan["coverage"] else ": a phone scan serves as well as a perfect one."),
    ]


def real_session_findings(plan_table: pd.DataFrame, closing: pd.DataFrame, agreement: pd.DataFrame) -> list[str]:
    """Notebook 10: the session's plan (``plan_table``), its closing checks (``closing``) and the
    agreement of today's exported model and the previous one with today's scan (``agreement``)."""
    planned = plan_table.iloc[0]
    stages = planned.filter(like=" (s)").astype(float)
    first, last = closing.iloc[0], closing.iloc[-1]
    by_model = agreement.set_index("model")
    ours, older = by_model.loc["today's exported model"], by_model.loc["the previous model"]
    return [
        f"The session asked for {len(planned['captured views'].split(', '))} captures before planning (the initial "
        f"view and the warm-up NBV), then planned {len(planned['planned views (path order)'].split(', '))} views on a "
        f"{planned['path length (m, world frame)']:.2f} m path in the previous model's frame; the longest planning "
        f"stage is the {stages.idxmax().removesuffix(' (s)')} ({stages.max():.2f} s of {stages.sum():.2f} s).",
        _percent("Once the planned views were captured, the closing check found", 100 * first["captured_coverage"],
                 "the plan's target", 100 * first["plan asks"], "of the corrected planning surface captured")
        + f"; over {len(closing)} checks it added {int(closing['views_added'].sum())} views, and the last found "
          f"{100 * last['captured_coverage']:.2f} % with {int(last['views_so_far'])} views "
        + ("(the target reached)." if last["captured_coverage"] >= last["plan asks"] else "(still short of the target)."),
        _percent("Today's exported model holds", 100 * ours["completeness"], "the previous model",
                 100 * older["completeness"], f"of today's scan within {ours['tolerance (mm)']:.2f} mm")
        + f", and {100 * ours['accuracy']:.2f} % of its points lie that close to the scan. Today's scan lies a median "
          f"{older['median reference -> model (mm)']:.2f} mm from the previous model, a day older, and "
          f"{ours['median reference -> model (mm)']:.2f} mm from today's: the previous model tells the session where "
          "to look, today's captures measure today's plant.",
    ]


def season_findings(summary: pd.DataFrame, totals: pd.DataFrame, rows_own, rows_truth, rows_none,
                    coverage_target: float) -> list[str]:
    """Notebook 11: the closed loop over the seasons (``summary``, ``totals`` per season and arm)
    and the greenhouse rows' totals per arm (``rows_own``, ``rows_truth``, ``rows_none``), each plan
    asking for ``coverage_target``."""
    target = 100 * coverage_target
    own_worst, truth_worst = summary["own_lowest_coverage"].min(), summary["truth_lowest_coverage"].min()
    below = sum(worst < target for worst in (own_worst, truth_worst))
    paths = totals.pivot_table(index=["view_space", "replan_after", "plant"], columns="arm", values="path_length_m")
    none_path = (paths["none"] / paths["truth"]).groupby(level=["view_space", "replan_after"]).mean()
    none_views = summary.set_index(["view_space", "replan_after"])["none_over_truth_views"]
    replanned = summary.groupby("replan_after")["own_lowest_coverage"].min()
    once, every = replanned.loc[0], replanned.loc[replanned.index.max()]
    rows_views = rows_own["total_views"] / rows_truth["total_views"]
    rows_none_path = rows_none["path_length_m"] / rows_truth["path_length_m"]
    higher = ("higher", "lower")
    return [
        _percent(f"Over {int(summary['seasons'].sum())} plant seasons, the `own` arm (planned from the robot's own "
                 "last reconstruction) sees", own_worst, "the `truth` arm", truth_worst,
                 "of today's plant in its worst session", words=higher)
        + f"; {['both reach', 'one of them falls below', 'both fall below'][below]} the {target:.0f} % each plan asks "
          f"for. It takes {_range(summary['own_over_truth_views'])}x the `truth` arm's views, and its fused model's "
          f"Chamfer distance to the plant drifts by at most {summary['own_drift_mm_max'].max():.2f} mm over a season.",
        f"With no prior, the geometric NBV (stopped when its true coverage reaches the target) needs "
        f"{_range(none_views)}x the `truth` arm's views over a season but {_range(none_path)}x its path: the previous "
        "session saves " + ("more path than views." if none_path.mean() > none_views.mean() else "more views than path."),
        _percent("Re-planning after every view leaves the `own` arm's worst session at", every, "the one-shot plans'",
                 once, "of today's plant", words=higher)
        + f": re-planning {'does not lift' if every <= once else 'lifts'} the worst session of a season.",
        _percent("On the greenhouse rows the `own` arm's worst session sees", rows_own["lowest_coverage"].min(),
                 "the `truth` arm's", rows_truth["lowest_coverage"].min(), "of the row", words=higher)
        + f", with {_range(rows_views)}x the `truth` arm's views; the block-wise NBV walks "
          f"{_range(rows_none_path, '.1f')}x the `truth` arm's path to reach "
          f"{rows_none['lowest_coverage'].min():.2f} % in its worst session.",
    ]
