"""Depth frames fused into one coloured surface cloud (:mod:`.tsdf`: TSDF integration, surface
extraction), each frame's pose first refined against the model fused so far (:mod:`.refine`)."""
