"""Fixtures of the ROS 2 over DDS tests: namespaces, domains and peers (see harness.py)."""

from tests.ros2.dds.harness import cyclonepeer, dds_domain, ddspeer, ddspeer_bin, netns


__all__ = ["cyclonepeer", "dds_domain", "ddspeer", "ddspeer_bin", "netns"]
