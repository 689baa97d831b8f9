"""The full-protocol result rows shipped with tpvp (tpvp/data/results): each protocol's file says
where it comes from, holds every (case, method) of its protocol, and reproduces the numbers the
README prints, to the printed digit."""

import re
import subprocess
from pathlib import Path

import pytest

from tpvp.experiments import plants, shipped, species
from tpvp.provenance import code_digest

ROOT = Path(__file__).resolve().parent.parent
#: Protocols whose rows were written before a refresh required a clean tree and recorded the code's
#: digest (issue 47); their pages say STALE. Empty since tables5_6 and species were refreshed (2026-11-28);
#: the set may only shrink.
WRITTEN_BEFORE_DIGESTS: set = set()
#: The suite's sample of `shipped verify`: tasks that took at most this long when shipped (about 30 s in all).
QUICK_TASK_S = 12


def _readme_row(label: str) -> str:
    rows = [line for line in (ROOT / "README.md").read_text().splitlines() if line.startswith(f"| {label} |")]
    assert len(rows) == 1, label
    return rows[0].split("|")[2].strip()


def _numbers(text: str) -> list[str]:
    return re.findall(r"\d+\.\d+", text)


@pytest.mark.parametrize("name", list(shipped.PROTOCOLS))
def test_every_protocol_is_shipped_whole_and_says_where_it_comes_from(name):
    assert shipped.shipped_rows(name) is not None, f"{name}: run python -m tpvp.experiments.shipped refresh {name}"
    entry = shipped.provenance()[name]
    assert re.fullmatch(r"[0-9a-f]{40}", entry["commit"]) and entry["command"].endswith(f"refresh {name}")
    assert entry["date_utc"] and entry["machine"] and entry["rows"] == len(shipped.shipped_rows(name))
    protocol = shipped.PROTOCOLS[name]
    rows = shipped.shipped_rows(name)
    assert set(rows["method"]) == set(protocol.methods)
    per_method = rows.groupby("method").size()
    if protocol.setting == "species":  # its dataset is grown by the data tools, not shipped
        ours = {(c.instance.name, c.view_space) for c in species.species_cases()}
        assert ours <= set(zip(rows["instance"], rows["view_space"]))
        assert (rows["source"] == "dataset").sum() >= 2 * 8 * 3  # 8 species x 3 plants, both view spaces
        return
    assert (per_method >= len(protocol.cases())).all(), per_method
    assert "shipped with tpvp, written on" in shipped.describe(name)


def _git(*args) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)


@pytest.mark.parametrize("name", list(shipped.PROTOCOLS))
def test_provenance_names_a_clean_commit_that_holds_the_protocol_and_the_codes_digest(name):
    entry = shipped.provenance()[name]
    assert "uncommitted" not in shipped.describe(name)
    if name in WRITTEN_BEFORE_DIGESTS:
        assert "digest" not in entry, f"{name} was refreshed: remove it from WRITTEN_BEFORE_DIGESTS"
        assert "; STALE: " in shipped.describe(name)
        return
    assert entry["clean"] is True and re.fullmatch(r"[0-9a-f]{64}", entry["digest"])
    if _git("cat-file", "-e", f"{entry['commit']}^{{commit}}").returncode != 0:
        if _git("rev-parse", "--is-shallow-repository").stdout.strip() == "true":
            pytest.skip(f"a shallow clone: commit {entry['commit'][:7]} is not here")
        pytest.fail(f"{name}: commit {entry['commit']} is in no history of this repository")
    source = _git("show", f"{entry['commit']}:tpvp/experiments/shipped.py").stdout
    assert f'"{name}": Protocol(' in source, f"commit {entry['commit'][:7]} has no protocol {name}"
    assert ("; STALE: " in shipped.describe(name)) == (entry["digest"] != code_digest())


def test_rows_of_another_tree_or_other_code_are_marked_stale(monkeypatch):
    entry = {"commit": "0" * 40, "date_utc": "2026-11-28T00:00:00+00:00", "command": "refresh", "machine": "x"}
    for fields, why in [({"dirty": True}, "a tree with changes beyond that commit"),
                        ({"clean": True, "digest": "f" * 64}, "code that differs from this checkout's"),
                        ({"clean": True, "digest": code_digest()}, None)]:
        monkeypatch.setattr(shipped, "provenance", lambda: {"table2": {**entry, **fields}})
        text = shipped.describe("table2")
        assert (why in text and "STALE" in text) if why else "STALE" not in text, text


def test_a_refresh_from_a_tree_with_changes_is_refused(monkeypatch):
    monkeypatch.setattr(shipped, "tree_state", lambda root: ("0" * 40, False))
    with pytest.raises(shipped.ConfigError, match="from a clean tree"):
        shipped.refresh(("table2",))


@pytest.mark.slow
def test_a_seeded_sample_of_quick_tasks_reproduces_the_shipped_rows(monkeypatch):
    reports = shipped.verify(("table1", "table1_learned"), sample=1, max_task_seconds=QUICK_TASK_S, progress=False)
    assert [r["protocol"] for r in reports] == ["table1", "table1_learned"]
    assert all(r["rows"] >= 1 and r["reproduced"] for r in reports), reports
    # the comparison can fail: the same task against shipped rows with one coverage changed
    rows = shipped.shipped_rows("table1")
    case, method = reports[0]["case"], reports[0]["method"]
    changed = rows.assign(coverage=rows["coverage"] + 1e-9)
    monkeypatch.setattr(shipped, "shipped_rows", lambda name: changed)
    again = shipped.verify(("table1",), sample=1, max_task_seconds=QUICK_TASK_S, progress=False)
    assert (again[0]["case"], again[0]["method"]) == (case, method)  # the same seeded sample
    assert again[0]["reproduced"] is False and "coverage" in again[0]["differing"]


def test_the_shipped_plant_rows_give_the_readmes_numbers():
    tables = plants.tables(shipped.shipped_rows("table1"))
    table1 = tables["table1_coverage_effort"]
    generated = table1[(table1["source"] == "generated") & (table1["method"] == "ours")].set_index("view_space")
    for space, label in (("hemisphere", "plants, hemisphere: Ours (views / coverage / path)"),
                         ("sphere", "plants, sphere: Ours")):
        row = generated.loc[space]
        shown = [f"{row[f'{c}_{s}']:.2f}" for c in ("views", "coverage", "path_length_m") for s in ("mean", "std")]
        assert _numbers(_readme_row(label)) == shown, (space, shown)
    ratio = tables["optimum_ratio"]
    ratio = ratio[(ratio["source"] == "generated") & (ratio["method"] == "ours")].set_index("view_space")
    shown = [f"{ratio.loc[space, 'views_ratio_mean']:.2f}" for space in ("hemisphere", "sphere")]
    assert _numbers(_readme_row("plants: Ours' views / the exact optimum's, same coverage")) == shown
    learned = table1[(table1["source"] == "generated") & (table1["method"] == "ma-scvp")].set_index("view_space")
    row = learned.loc["hemisphere"]
    shown = [f"{row[f'{c}_{s}']:.2f}" for c in ("views", "coverage", "path_length_m") for s in ("mean", "std")]
    assert _numbers(_readme_row("learned MA-SCVP, hemisphere")) == shown


def test_the_shipped_row_rows_give_the_readmes_numbers():
    from tpvp.experiments import rows

    table6 = rows.tables(shipped.shipped_rows("tables5_6"))["table6_coverage_effort"]

    def ours(reference, method="ours", cover=4.0):
        picked = table6[(table6["reference"] == reference) & (table6["method"] == method)]
        if cover is not None:
            picked = picked[picked["cover_resolution_cm"] == cover]
        assert len(picked) == 1, (reference, method)
        return picked.iloc[0]

    row = ours("handheld")
    shown = [f"{row['views_mean']:.1f}", f"{row['views_std']:.1f}", f"{row['coverage_mean']:.2f}",
             f"{row['coverage_std']:.2f}", f"{row['path_length_m_mean']:.1f}", f"{row['path_length_m_std']:.1f}"]
    assert _numbers(_readme_row("greenhouse rows: Ours at 4 cm, handheld reference")) == shown
    shown = [f"{ours(r)[c]:.2f}" for r in ("candidates", "complete") for c in ("coverage_mean", "coverage_std")]
    assert _numbers(_readme_row("rows: the same, candidate-filtered / complete reference")) == shown
    shown = [f"{ours(r, 'coarse', None)['coverage_mean']:.2f}" for r in ("handheld", "candidates", "complete")]
    assert _numbers(_readme_row("rows: passive sweep, handheld / candidates / complete reference")) == shown


def test_the_shipped_pose_noise_rows_give_the_readmes_numbers():
    from tpvp.experiments import rows
    from tpvp.experiments.pose_noise import in_paper_units

    table7 = in_paper_units(rows.tables(shipped.shipped_rows("table7"))["table7_pose_noise"])
    noisy = table7[(table7["sigma_t_m"] == 0.01) & (table7["sigma_r_deg"] == 2) & (table7["icp"] == "ON")].iloc[0]
    shown = [f"{noisy['chamfer_mm_mean']:.2f}", f"{noisy['chamfer_mm_std']:.2f}", f"{noisy['f1_10mm_mean']:.1f}"]
    assert _numbers(_readme_row("rows, pose noise 0.01 m / 2°, with ICP: Chamfer, F1")) == shown


def test_the_shipped_species_rows_give_the_readmes_numbers():
    overall = species.species_tables(shipped.shipped_rows("species"))["overall"].set_index("view_space")
    shown = [value for space in ("hemisphere", "sphere")
             for value in (f"{100 * overall.loc[space, 'coverage_mean']:.2f}",
                           f"{100 * overall.loc[space, 'coverage_min']:.2f}",
                           f"{overall.loc[space, 'views_per_optimum']:.2f}")]
    label = "6 Helios evaluation species, asking for 98 %: true coverage mean (min), views / exact optimum"
    assert _numbers(_readme_row(label)) == shown
