"""Bridges from the fleet to the robotics toolbox (docs/ros2.md).

- ``names``: fleet and vehicle names as ROS names (``exp2a-features`` -> ``exp2a_features``), topics and frames;
- ``rmw_zenoh``: the rmw_zenoh wire format (data keys, liveliness tokens, attachments, GIDs) and a minimal ROS 2
  node that publishes in it;
- ``ros_msgs``: ROS 2 messages (CDR, RIHS01 type hashes) through ``rosbags``;
- ``translate``: one fleet message -> the ROS 2 messages that mirror it;
- ``tap``: a raw subscriber on every key of a fleet, feeding a worker thread;
- ``mirror``: ``evopose ros2``; ``listener``: a pure-Python rmw_zenoh subscriber (graph from liveliness tokens);
- ``recording``: ``evopose record`` / ``replay`` (MCAP, ROS 2 profile plus the raw channels);
- ``view``: ``evopose view`` (a Foxglove WebSocket server).

Heavy imports (zenoh, rosbags, mcap, foxglove) are made by the modules that need them; this face imports nothing.
"""
