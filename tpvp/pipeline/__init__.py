"""From what the robot knows to a plan: the planners of one plant (:mod:`.plant`) and of a greenhouse
row (:mod:`.row`). They read what the robot knows, never the simulator's ground truth; the
simulation (:mod:`tpvp.simulate`) and a real session (:mod:`tpvp.session`) both call them."""
