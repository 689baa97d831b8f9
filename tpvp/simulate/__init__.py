"""The simulated world: a plan executed on the ground truth, the cases it runs on, the stand-ins.

What both the product commands (``tpvp demo``, ``plan``, ``greenhouse``, ``render``) and the
paper's experiments (:mod:`tpvp.experiments`) call: the simulated world of a session pair (both scans
in the planning frame, today's ground truth and what each view observes: :mod:`~tpvp.simulate.world`),
a plant case (:mod:`~tpvp.simulate.single_plant`) and a row case (:mod:`~tpvp.simulate.greenhouse`)
executed end to end on the ground truth, what a simulated run leaves (:mod:`~tpvp.simulate.outputs`),
the coverage-effort frontier (:mod:`~tpvp.simulate.frontier`) beside the exact optimum with perfect
knowledge (:mod:`~tpvp.simulate.optimum`), the render smoke run (:mod:`~tpvp.simulate.render_demo`), the
case definitions of the rows (:mod:`~tpvp.simulate.row_cases`) and the stand-in camera that plays a
robot for a real session (:mod:`~tpvp.simulate.robot_camera`). :mod:`tpvp.experiments` keeps the
protocols, the measurements and their tables; nothing here imports it.
"""
