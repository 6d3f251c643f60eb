"""Live ROS: a depth-completion node that subscribes a robot's topics and publishes depth.

- :mod:`.transport`: the one interface every transport implements (they only move messages).
"""
