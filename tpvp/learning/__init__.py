"""Learned view-planning baselines trained on generated plants (docs/learning.md).

scan states of generated plants (:mod:`.dataset`) -> input grid / cloud (:mod:`.grid`) ->
networks (:mod:`.models`) -> training (:mod:`.training`) -> weight files (:mod:`.weights`) ->
stage methods ``ma-scvp`` (view selection) and ``pc-nbv`` (NBV) (:mod:`.planners`).

Importing this package imports torch; the pipeline imports it only when a learned method is used.
"""
