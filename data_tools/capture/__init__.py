"""A phone's capture into a session's cloud: read the capture's frames (:mod:`.formats`), fuse their
depth (:mod:`.fusion`); and a stand-in phone that writes such captures of generated plants and rows
(:mod:`.phone_standin`)."""
