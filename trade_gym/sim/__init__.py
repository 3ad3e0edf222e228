"""Simulator components: world, vehicles, quadrotor and its sensors (pybullet, one client per env)."""
