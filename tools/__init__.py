"""Project tooling, not the library: the notebook runner (:mod:`tools.notebooks`) and the
documentation site builder (:mod:`tools.site`)."""
