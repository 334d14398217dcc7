"""The MuJoCo world a sim steps: its model, robots, sensors, controllers and the mirrors of other sims' robots. Imports
no zenoh (an import-linter contract): the serving and replica rooms do the I/O.
"""
