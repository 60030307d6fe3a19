"""A Zenoh router for the local stack (no zenohd needed: a router-mode session is one)."""
