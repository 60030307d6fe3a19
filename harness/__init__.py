"""What the tests and the benchmarks share, from a checkout (never installed): child
processes that are always stopped (`processes`), free ports (`ports`), bounded waits
(`wait`), the supervisor seen from a test or a benchmark (`client`), the whole stack up
(`stack`), what the benchmarks measure with (`measure`), the speech set the recogniser is
tuned and measured on (`speech_set`), a robot under every fault STOP must beat
(`stop_rig`), a robot of real ROS 2 in a namespace (`ros2_rig`), two hosts in network
namespaces (`netns`, `cross_host`), and the list of what CI skipped (`skips`)."""
