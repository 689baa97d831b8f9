"""The ``tpvp`` commands: each module adds its commands' options and handlers to the parser
:mod:`tpvp.cli` builds, and is loaded only when one of its commands runs."""
