"""Set-cover view selection: the fewest candidate views that see every planning-surface voxel."""
