"""Next-best-view methods: geometric information gain on an occupancy map of what was observed, and
the prior-guided gain on the previous session (each registers itself in ``NBV_METHODS``; the
prior-guided one is a registry plugin, :data:`tpvp.registry.BUILTIN_PLUGINS`). The package imports
nothing: its configuration, :mod:`tpvp.nbv.config`, loads no kernel."""
