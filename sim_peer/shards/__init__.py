"""A world served by several sims: which sim serves which robots, the mirrors fed from the others, and moving a robot
between sims.
"""
