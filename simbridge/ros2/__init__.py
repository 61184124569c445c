"""What ROS 2 transports share, and each of them (DDS here; Zenoh moves in)."""
