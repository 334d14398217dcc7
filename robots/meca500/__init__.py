"""The Mecademic Meca500: geometry (the single source) and the generator of its URDF, MJCF and robot.toml."""
