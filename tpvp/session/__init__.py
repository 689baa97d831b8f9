"""Real sessions: plan today's views from the previous session's model and the robot's first captures."""

from tpvp.session.captures import Pose, back_project, read_depth, read_intrinsics, read_pose_file
from tpvp.session.plant import Request, Session, SessionScene, session_config

__all__ = ["Pose", "Request", "Session", "SessionScene", "back_project", "read_depth", "read_intrinsics",
           "read_pose_file", "session_config"]
