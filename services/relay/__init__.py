"""The STOP relay: where a robot on DDS is stopped by processes that have Zenoh alone."""
