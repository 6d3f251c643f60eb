"""Live ROS: a depth-completion node that subscribes a robot's topics and publishes depth.

- :mod:`.transport`: the one interface every transport implements (they only move messages).
- :mod:`.dds`: ROS 2 over DDS (``cyclonedds``, extra ``ros2``), no ROS installation needed.
- :mod:`.node`: the node (``semattnet ros2``); :mod:`.inputs`: its decoding and stamp pairing; :mod:`.names`:
  ROS name resolution.
"""
