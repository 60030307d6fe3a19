"""What the tests and the benchmarks share, from a checkout (never installed): child
processes that are always stopped (`processes`), the speech set the recogniser is tuned
and measured on (`speech_set`), and two hosts in network namespaces (`netns`)."""
