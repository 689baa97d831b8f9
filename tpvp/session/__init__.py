"""Real sessions: plan today's views from the previous session's model and the robot's first
captures (single plants and greenhouse rows), no ground truth."""

from tpvp.sensor.images import read_depth, read_intrinsics
from tpvp.session.captures import Pose, back_project, read_pose_file
from tpvp.session.folder import Request, Session
from tpvp.session.plant import PlantSession
from tpvp.session.row import RowSession

__all__ = ["PlantSession", "Pose", "Request", "RowSession", "Session", "back_project", "read_depth",
           "read_intrinsics", "read_pose_file"]
