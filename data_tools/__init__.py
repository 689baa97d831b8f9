"""Data tools for tpvp: download and clean the public data, prepare new monitoring sessions.

* :mod:`data_tools.pheno4d` - the Pheno4D single-plant scans (download, prepare a clean dataset).
* :mod:`data_tools.helios` - plants grown by Helios (optional pyhelios3d), organ-labelled, in the same
  prepared layout (:mod:`data_tools.prepared`).
* :mod:`data_tools.greenhouse` - the greenhouse multi-session row dataset (Kaggle download, cleaning,
  alignment of every session to the first day).
* :mod:`data_tools.sessions` - a user's new scan into an existing dataset (``prepare-session``).

Command line: ``python -m data_tools --help``. Every error the user can fix is a
:class:`tpvp.errors.TpvpError` with a one-line message naming the file or field.
"""
