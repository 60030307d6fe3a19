"""The benchmarks, from a checkout (never installed): each runs as
`.venv/bin/python -m bench.<name>` from the repository root, prints its figures beside a
baseline, and takes what it measures with from `harness/`, never from another benchmark or
from the tests (docs/benchmarks.md has the commands and the numbers)."""
