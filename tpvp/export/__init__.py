"""What tpvp hands to other software, one module per target; the commands are ``tpvp export``
(:mod:`tpvp.commands.export`).

A plan (``plan.csv``, :mod:`tpvp.io.plan`) moved into a robot's base frame by a rigid
base-from-scan transform (:mod:`.poses`):

- :mod:`.moveit`: MoveIt pose goals (YAML), the camera's pose at each view;
- :mod:`.ros2`: a ROS 2 bag (rosbag2, MCAP storage) with the views as a ``PoseArray`` and a
  ``Path`` and the static transform, for ``ros2 bag play``, RViz or a planner node.

A session's captures (or a plan's views) handed to reconstruction tools, with the colour images the
robot kept (:mod:`.images`):

- :mod:`.nerfstudio`: ``transforms.json`` and the initial points, for ``ns-train``;
- :mod:`.colmap`: a COLMAP text model with known poses, for COLMAP's ``point_triangulator`` or
  ``pycolmap``.
"""
