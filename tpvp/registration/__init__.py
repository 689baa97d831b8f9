"""Non-rigid registration of the previous session onto the current coarse reconstruction."""
