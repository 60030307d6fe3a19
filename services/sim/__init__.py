"""`voicectl sim`: a 2-D robot that speaks ROS 2 the way zenoh-bridge-ros2dds exposes it."""
