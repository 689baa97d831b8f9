"""`tpvp export moveit`: a plan's views as MoveIt pose goals in the robot's base frame, read back
with the YAML reader MoveIt's tools use; a transform that is not rigid is one line, nothing written."""

import numpy as np
import pandas as pd
import pytest
import yaml

from tpvp.cli import main
from tpvp.io.plan import plan_table, write_plan
from tpvp.pipeline.robot import quaternion_to_rotation
from tpvp.sensor.camera import look_at_rotations, rotation_to_quaternion


@pytest.fixture
def plan_folder(tmp_path):
    rng = np.random.default_rng(7)
    positions = rng.normal(size=(6, 3))
    look_ats = 0.1 * rng.normal(size=(6, 3))
    quaternions = [rotation_to_quaternion(r) for r in look_at_rotations(positions, look_ats)]
    roles = ["initial", "warm-up NBV"] + ["planned"] * 4
    write_plan(tmp_path, {"scan": plan_table(positions, look_ats, quaternions, roles)}, {"scan": "the scans' frame"})
    return tmp_path


def _rigid(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    matrix = np.eye(4)
    matrix[:3, :3] = q * np.sign(np.linalg.det(q))
    matrix[:3, 3] = rng.normal(size=3)
    return matrix


def test_moveit_goals_are_the_plan_in_the_base_frame(plan_folder, tmp_path, capsys):
    matrix = _rigid(np.random.default_rng(3))
    (tmp_path / "base.yaml").write_text(yaml.safe_dump({"matrix": matrix.tolist()}))
    out = tmp_path / "goals.yaml"
    assert main(["export", "moveit", str(plan_folder), "--base-from-scan", str(tmp_path / "base.yaml"),
                 "--frame", "panda_link0", "--output", str(out)]) == 0
    assert "6 pose goals in frame 'panda_link0'" in capsys.readouterr().out
    goals = yaml.safe_load(out.read_text())
    plan = pd.read_csv(plan_folder / "plan.csv", comment="#")
    assert goals["frame_id"] == "panda_link0" and [g["step"] for g in goals["pose_goals"]] == plan["step"].tolist()
    for goal, row in zip(goals["pose_goals"], plan.itertuples()):
        position = [goal["position"][a] for a in "xyz"]
        assert np.allclose(position, matrix[:3, :3] @ [row.x, row.y, row.z] + matrix[:3, 3], atol=1e-9)
        orientation = quaternion_to_rotation([goal["orientation"][a] for a in "xyzw"])
        assert np.allclose(orientation, matrix[:3, :3] @ quaternion_to_rotation([row.qx, row.qy, row.qz, row.qw]),
                           atol=1e-9)
        assert goal["role"] == row.role


def test_without_a_transform_the_goals_are_the_plan(plan_folder, tmp_path):
    out = tmp_path / "goals.yaml"
    assert main(["export", "moveit", str(plan_folder / "plan.csv"), "--output", str(out)]) == 0
    plan = pd.read_csv(plan_folder / "plan.csv", comment="#")
    for goal, row in zip(yaml.safe_load(out.read_text())["pose_goals"], plan.itertuples()):
        assert [goal["position"][a] for a in "xyz"] == pytest.approx([row.x, row.y, row.z], abs=1e-12)
        q = np.array([goal["orientation"][a] for a in "xyzw"])
        assert min(np.abs(q - [row.qx, row.qy, row.qz, row.qw]).max(),
                   np.abs(q + [row.qx, row.qy, row.qz, row.qw]).max()) < 1e-12  # q and -q: one rotation


@pytest.mark.parametrize("matrix,expected", [
    (np.diag([2.0, 2.0, 2.0, 1.0]).tolist(), "not a rigid transform"),
    ([[1, 0, 0], [0, 1, 0]], "4x4 matrix"),
    ("no matrix here", "4x4 matrix"),
])
def test_a_transform_that_is_not_rigid_is_one_line_and_nothing_is_written(plan_folder, tmp_path, capsys, matrix,
                                                                          expected):
    (tmp_path / "base.json").write_text(yaml.safe_dump(matrix))
    out = tmp_path / "goals.yaml"
    assert main(["export", "moveit", str(plan_folder), "--base-from-scan", str(tmp_path / "base.json"),
                 "--output", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0] and "base.json" in err[0] and not out.exists()


def test_a_missing_plan_is_one_line(tmp_path, capsys):
    assert main(["export", "moveit", str(tmp_path / "nowhere"), "--output", str(tmp_path / "g.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such plan" in err[0]
