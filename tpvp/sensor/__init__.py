"""The virtual sensor (the pinhole camera, the voxel ray casting, the two measurement models and
their brute-force twin) and a depth camera's files (:mod:`.images`: intrinsics, depth images).
What tpvp hands to reconstruction tools is in :mod:`tpvp.export`."""
