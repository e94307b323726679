"""Edges from real drones to the contract (Crazyflie over cflib; later ROS 2, MAVLink)."""
